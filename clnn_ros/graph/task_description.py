"""The environment's task as the graph carries it: the latched TaskDescription on env/task
(contract version 4, docs/ENV_CONTRACT.md), turned into a core Task and checked against the
run's parameters, and the checks an observation gets once the task is known. No ROS import: the
offline tools read recorded descriptions with it too."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..core.params import ParamError, Params
from ..core.task import Action, Task, Variable
from .names import ENV_CONTRACT_VERSION, OLDER_STATE, TASK

# TrialEvent.end_reason of a trial that terminated for a reason its task does not name
TERMINATED = "terminated"
# Why the graph does not start with an environment node that publishes on names.OLDER_STATE.
OLDER_CONTRACT = (f"the environment node speaks contract version 3 or older (it publishes "
                  f"{OLDER_STATE}, no {TASK}): docs/ENV_CONTRACT.md, \"Versions\", says what to "
                  f"change for version {ENV_CONTRACT_VERSION}")


@dataclass(frozen=True)
class Described:
    """A task description as received: the task, and the names of its ways to terminate."""

    task: Task
    termination_reasons: tuple[str, ...] = ()

    def fields(self) -> dict:
        """The TaskDescription message's fields."""
        task = self.task
        return dict(contract_version=ENV_CONTRACT_VERSION, task=task.name,
                    variable_names=list(task.names), variable_units=list(task.units),
                    variable_low=[v.low for v in task.variables],
                    variable_high=[v.high for v in task.variables],
                    action_labels=list(task.action_labels),
                    action_values=[a.value for a in task.actions],
                    max_steps=task.max_steps or 0,
                    reward_threshold=math.nan if task.reward_threshold is None
                    else float(task.reward_threshold),
                    ends_in=task.ends_in, termination_reasons=list(self.termination_reasons))

    def end_reason(self, termination: int) -> str:
        """A terminated trial's TrialEvent.end_reason from its Observation.termination."""
        reasons = self.termination_reasons
        return reasons[termination - 1] if 0 < termination <= len(reasons) else TERMINATED

    def observation_problem(self, values) -> str | None:
        """Why an observation's values do not fit the task (their count), or None. Values
        outside the declared bounds are not refused: as in Gymnasium, whose spaces' bounds some
        tasks do not keep (LunarLander-v3's angle passes 2 pi in flight), a bound is what the
        values are expected in; the checker (clnn-check-env) says where they leave it."""
        variables = self.task.variables
        if len(values) != len(variables):
            return f"{len(values)} values, the task {self.task.name} has {len(variables)} " \
                   f"variables ({', '.join(self.task.names)})"
        return None


def described(msg) -> Described:
    """The Described of a TaskDescription message; ParamError with one line where it is not a
    version-4 description of a task."""
    if msg.contract_version != ENV_CONTRACT_VERSION:
        raise ParamError(f"it speaks contract version {msg.contract_version}, the graph "
                         f"version {ENV_CONTRACT_VERSION} (docs/ENV_CONTRACT.md, \"Versions\")")
    names, units = list(msg.variable_names), list(msg.variable_units)
    lows, highs = list(msg.variable_low), list(msg.variable_high)
    labels, values = list(msg.action_labels), list(msg.action_values)
    if not len(names) == len(units) == len(lows) == len(highs):
        raise ParamError(f"{len(names)} variable names, {len(units)} units, {len(lows)} lows "
                         f"and {len(highs)} highs: one each per variable")
    if len(labels) != len(values):
        raise ParamError(f"{len(labels)} action labels and {len(values)} action values")
    if any(math.isnan(x) or lo > hi for lo, hi in zip(lows, highs) for x in (lo, hi)):
        raise ParamError("a variable's bounds are NaN or low > high")
    max_steps = msg.max_steps or None
    threshold = None if math.isnan(msg.reward_threshold) else msg.reward_threshold
    task = Task(msg.task, tuple(Variable(*v) for v in zip(names, units, lows, highs)),
                tuple(Action(*a) for a in zip(labels, values)), max_steps, threshold, msg.ends_in)
    return Described(task, tuple(msg.termination_reasons))


def description_problem(msg, p: Params) -> str | None:
    """Why an environment's TaskDescription does not fit the run (p), or None."""
    try:
        task = described(msg).task
        task.check(p)
    except ParamError as error:
        return str(error)
    return None
