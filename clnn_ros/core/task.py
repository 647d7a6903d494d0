"""A task, described without knowing it: what its observation's variables are (names, units,
bounds), its actions (K >= 2: one RLN each), what ends an episode, and its own "solved"
threshold where it has one.

The paper's cart-pole is one task (CARTPOLE below); any Gymnasium task with a Box observation
and a Discrete action space (or a Box one with a declared set of values) is another
(clnn_ros.tasks.gymnasium builds its Task from its spaces and spec). The agent, the encoder and
the rule read only this: a new task touches its own room, not them.

An episode of a task ends when its step says `terminated` (the task is over: a failure, such as
the pole falling, or a success, such as reaching a goal: `ends_in` says which, and so which
reward mapping fits it, Params.reward_mapping) or `truncated` (its time ran out: no failure, no
success).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .encoder import STATE_UNITS
from .params import CARTPOLE, STATE_NAMES, ParamError, Params, params_from_strings

ENDS_IN = ("failure", "success")  # what a terminated episode means
REWARD_MAPPING_OF = {"failure": "failure", "success": "goal"}  # ends_in -> Params.reward_mapping


@dataclass(frozen=True)
class Variable:
    """One component of the observation: its name (a word), its unit, its bounds."""

    name: str
    unit: str = ""
    low: float = -math.inf
    high: float = math.inf


@dataclass(frozen=True)
class Action:
    """One of the task's actions: a label for people, and what it applies (a Gymnasium task's
    Discrete index or declared Box value; the cart-pole's force direction)."""

    label: str
    value: float


@dataclass(frozen=True)
class Task:
    name: str
    variables: tuple[Variable, ...]
    actions: tuple[Action, ...]
    max_steps: int | None = None  # an episode is truncated after this many steps (None: never)
    reward_threshold: float | None = None  # the task's own "solved" (mean return), if any
    ends_in: str = "failure"  # ENDS_IN

    def __post_init__(self) -> None:
        names = self.names
        if len(self.actions) < 2:
            raise ParamError(f"task {self.name}: it needs 2 or more actions, got "
                             f"{len(self.actions)}")
        if not names or len(set(names)) != len(names) or \
                not all(n.isidentifier() for n in names):
            raise ParamError(f"task {self.name}: its variables need distinct names of letters, "
                             f"digits and _, got {list(names)}")
        if self.ends_in not in ENDS_IN:
            raise ParamError(f"task {self.name}: ends_in must be one of {ENDS_IN}, "
                             f"got {self.ends_in!r}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.variables)

    @property
    def units(self) -> tuple[str, ...]:
        return tuple(v.unit for v in self.variables)

    @property
    def action_labels(self) -> tuple[str, ...]:
        return tuple(a.label for a in self.actions)

    def params(self, values: dict[str, str] | None = None, base: Params | None = None) -> Params:
        """`base` (default: the paper's values) made this task's (its name, its actions, its
        truncation, the reward mapping of how its episodes end), then `values` (text, as a
        command gives them) over it; every variable of the task encoded where p still encodes
        the cart-pole's (each then needs its edges in variable_edges). ParamError with one line
        where the result does not fit the task."""
        p = base or Params()
        if self.name != CARTPOLE:
            p = p.replace(**self.own_values())
        p = params_from_strings(values or {}, p)
        if self.name != CARTPOLE and all(v in STATE_NAMES for v in p.state_vars):
            edged = {name for name, _ in p.variable_edges}
            missing = [v for v in self.variables if v.name not in edged]
            if missing:
                raise ParamError(f"task {self.name}: variable_edges has no edges for "
                                 f"{missing[0].name} (bounds {missing[0].low:g} to "
                                 f"{missing[0].high:g}), e.g. "
                                 f"--option variable_edges='{missing[0].name}:-1,0,1'")
            p = p.replace(state_vars=self.names)
        self.check(p)
        return p

    def own_values(self) -> dict:
        """The values a task sets whatever it encodes: its name, its actions' count, its
        truncation and the reward mapping of how its episodes end."""
        return dict(task=self.name, n_actions=len(self.actions),
                    reward_mapping=REWARD_MAPPING_OF[self.ends_in],
                    **({} if self.max_steps is None else {"max_steps": self.max_steps}))

    def check(self, p: Params) -> None:
        """ParamError with one line where p is not for this task."""
        if p.task != self.name:
            raise ParamError(f"the parameters are for task {p.task!r}, not {self.name!r}")
        if p.n_actions != len(self.actions):
            raise ParamError(f"task {self.name} has {len(self.actions)} actions "
                             f"({', '.join(self.action_labels)}); n_actions is {p.n_actions}")
        unknown = [v for v in p.state_vars if v not in self.names]
        if unknown:
            raise ParamError(f"task {self.name} has no variable {unknown[0]!r}; it has "
                             f"{', '.join(self.names)}")


# The paper's cart-pole (its state in the core's units; actions: neuron 0 pushes with -F, 1 with
# +F); its episode length is Params.max_steps, its protocol Params.protocol.
CARTPOLE_TASK = Task(
    CARTPOLE,
    tuple(Variable(name, unit) for name, unit in zip(STATE_NAMES, STATE_UNITS)),
    (Action("-F", -1.0), Action("+F", 1.0)))


def cartpole_task(p: Params) -> Task:
    """The paper's cart-pole with its limits as bounds (a state beyond one terminates: the cart's
    position and the pole's angle) and its truncation at p.max_steps."""
    limits = {"cart_position": p.track_limit_m, "pole_angle": p.angle_limit_deg}
    return Task(CARTPOLE,
                tuple(Variable(v.name, v.unit, -limits.get(v.name, math.inf),
                               limits.get(v.name, math.inf)) for v in CARTPOLE_TASK.variables),
                CARTPOLE_TASK.actions, p.max_steps)
