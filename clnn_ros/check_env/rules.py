"""The rules of the environment contract (docs/ENV_CONTRACT.md, version 4) as clnn-check-env
reports them, the checked run, and the rules of a published task description and observation.
In the manner of Gymnasium's env_checker, each check_* function checks one thing of what the
node did and yields what is wrong with it (the text of a FAIL line); nothing when the node keeps
the rule. No ROS import: a rule reads message fields, so RULES is read without rclpy."""

from __future__ import annotations

import math
from typing import Iterable, Iterator

from ..core.params import CARTPOLE, INTEGRATORS, PHYSICS, ParamError, Params
from ..core.physics import (in_degrees, physics_constants, physics_step, start_in_units,
                            state_in_radians)
from ..core.task import cartpole_task
from ..graph.content import observation_problem
from ..graph.fields import CARTPOLE_TERMINATIONS, tick_nanoseconds
from ..graph.names import (ACTION, CLOCK, ENV_CONTRACT_VERSION, OLDER_STATE, READY, STATE, TASK,
                           TOPIC_TYPES, TRIAL_EVENT)
from ..graph.run import run_values
from ..graph.task_description import Described, described
from ..session.process_signals import EXIT_WITH_STDIN

RULES = {
    "starts": "the command starts a node that keeps running",
    "readiness": f"announces 'environment' on {READY} (TRANSIENT_LOCAL) once {STATE} has 3 "
                 f"subscribers",
    "interface": f"node 'environment' in the namespace it is given; subscribes {CLOCK}, "
                 f"{TRIAL_EVENT}, {ACTION}; publishes {STATE} (RELIABLE, VOLATILE) and {TASK} "
                 f"(RELIABLE, TRANSIENT_LOCAL); relative names, clnn_ros_msgs types",
    "task": f"{TASK}: a TaskDescription of contract version {ENV_CONTRACT_VERSION}, valid, of "
            f"the run's task and n_actions, latched (a subscriber that joins later gets it)",
    "sim_time": "use_sim_time is true",
    "lockstep": "observation(t) once, only after clock(t) and START(t) or action(t-1); tick t "
                "and the trial",
    "reset": "START resets: successful_steps 0, reward 0, not terminated nor truncated, the "
             "START's trial (the cart-pole: cart at 0 and at rest, pole at rest at "
             "initial_angle_deg)",
    "observation": "finite values and reward, as many values as the task has variables (their "
                   "bounds are expected, not refused; the cart-pole's limits: termination)",
    "successful_steps": "+1 per step that does not terminate, not for the terminating one",
    "truncation": "truncated when successful_steps reaches max_steps (or the task's own), not "
                  "before; then ACTION_NONE answers, no observation follows until START",
    "termination": "termination 1 + an index of termination_reasons, only with terminated "
                   "(the cart-pole: 1 pole_angle beyond angle_limit_deg, else 2 cart_position "
                   "beyond track_limit_m, terminated exactly then)",
    "actions": "each action index 0..K-1 is applied (the cart-pole: 0 pushes toward -x, 1 "
               "toward +x); ACTION_NONE may come after the next START and clock",
    "refusals": "refuses an action index that does not exist, ACTION_NONE mid-trial, an action "
                "or clock of another tick, START mid-trial (the cart-pole: START outside the "
                "angle limit)",
    "episode_end": "exits with status 0 on EPISODE_END",
    "stdin_eof": f"with {EXIT_WITH_STDIN}=1, exits when its stdin reaches end of file",
}
# Advisory unless --physics-from-run, and the cart-pole's only: a simulator of its own
# (gymnasium, friction, a robot) steps other physics than the run's and keeps the contract.
PHYSICS_RULE = {
    "physics": "the observations follow the run's cart-pole: the equations of "
               "docs/ENV_CONTRACT.md with the physics parameters of the run's file",
}
STRICT_PHYSICS = "--physics-from-run"
NAME = "environment"  # the checked node's name
MAX_STEPS = 60  # the cap the checked node gets; the terminating trial must end before it
ANGLE_LIMIT_DEG, TRACK_LIMIT_M, TAU = 12.0, 2.4, 0.02  # the defaults it gets
# The run's values the harness and the rules depend on: no --option changes them.
FIXED = ("max_steps", "tau", "force", "angle_limit_deg", "track_limit_m", "protocol",
         "first_action")
# The values of the command's own `-p NAME:=VALUE` the checker takes as the run's: what the task
# is (under run_all the run's file would win over them; docs/ENV_CONTRACT.md).
TASK_PARAMETERS = ("task", "n_actions")
# The cart-pole of the checker's run: the paper's equations with masses, length and gravity
# other than the defaults, so that a node that keeps the defaults instead of reading the run's
# file is told. Force, tau and the limits stay the defaults: the harness and the rules use them.
RUN_PHYSICS = {"cart_mass": 0.9, "pole_mass": 0.15, "pole_length": 0.4, "gravity": 9.81}
CHECKED_RUN = Params(max_steps=MAX_STEPS, **RUN_PHYSICS)
UNITS = {"cart_mass": "kg", "pole_mass": "kg", "pole_length": "m", "gravity": "m/s^2"}
# An observation follows the physics within this (relative, absolute): a node may work in radians.
PHYSICS_TOLERANCE = (1e-6, 1e-9)
TAU_NS = tick_nanoseconds(TAU)
TYPES = {topic: TOPIC_TYPES[topic] for topic in (STATE, TASK, CLOCK, TRIAL_EVENT, ACTION)}
SHOWN_PER_RULE = 3  # FAIL lines per rule; more problems are counted


class Abort(Exception):
    """The node stopped answering: the remaining rules cannot be checked."""


class Findings:
    """The problems found per rule (the first SHOWN_PER_RULE of each, the others counted), the
    rules checked at all, notes on what a rule could not see, and whether the node speaks an
    older contract (then that one line is the report)."""

    def __init__(self, strict_physics: bool = False):
        self.problems = {rule: [] for rule in {**RULES, **PHYSICS_RULE}}
        self.checked = set()
        self.more = {}  # rule: problems found beyond those shown
        self.notes = {}  # rule: what it did not see (shown with its PASS line)
        self.strict_physics = strict_physics  # physics a rule, not advice
        self.physics_skipped = ""  # why the physics rule does not apply (not the cart-pole)
        self.older = ""  # the one line for a node of an older contract version

    def fail(self, rule: str, text: str) -> None:
        if text in self.problems[rule]:
            return
        if len(self.problems[rule]) < SHOWN_PER_RULE:
            self.problems[rule].append(text)
        else:
            self.more[rule] = self.more.get(rule, 0) + 1

    def fail_all(self, rule: str, problems: Iterable[str]) -> None:
        for text in problems:
            self.fail(rule, text)

    def not_checked(self, rule: str, why: str) -> None:
        """The rule was reached but could not be checked: a FAIL line that says why."""
        self.problems[rule].append(f"not checked: {why}")

    def report(self) -> bool:
        """A PASS, FAIL or SKIP line per rule (physics: WARN instead of FAIL unless strict);
        True when every rule passes. A node of an older contract gets its one line."""
        if self.older:
            print(f"FAIL  task: {self.older}")
            return False
        ok = True
        for rule, meaning in {**RULES, **PHYSICS_RULE}.items():
            problems = self.problems[rule]
            binding = rule in RULES or self.strict_physics
            if rule == "physics" and self.physics_skipped:
                print(f"SKIP  physics: {self.physics_skipped}")
            elif rule not in self.checked:
                print(f"SKIP  {rule}: not checked (an earlier failure stopped the check)")
                ok = ok and not binding
            elif problems:
                ok = ok and not binding
                for text in problems:
                    print(f"{'FAIL' if binding else 'WARN'}  {rule}: {text}")
                if not binding:
                    print(f"WARN  {rule}: fine for a simulator of its own (gymnasium, friction, "
                          f"a robot); {STRICT_PHYSICS} makes this a FAIL")
                if self.more.get(rule):
                    print(f"FAIL  {rule}: ... and {self.more[rule]} more like these")
            else:
                note = f" ({self.notes[rule]})" if rule in self.notes else ""
                print(f"PASS  {rule}: {meaning}{note}")
        return ok


# --- the checked run -------------------------------------------------------------------------

def command_task_options(command: list[str]) -> dict:
    """The command's own `-p task:=...` and `-p n_actions:=...` (after --ros-args): the checker
    takes them as the run's, since the run's file it appends would win over them."""
    found, ros_args = {}, False
    for flag, value in zip(command, command[1:]):
        ros_args = ros_args or flag == "--ros-args"
        if ros_args and flag in ("-p", "--param") and ":=" in value:
            name, text = value.split(":=", 1)
            if name in TASK_PARAMETERS:
                found[name] = text
    return found


def checked_run(options: dict) -> tuple[dict, Params]:
    """The values of the checker's run file (what a run's file holds for an environment,
    graph.run.ENVIRONMENT_GIVEN: max_steps 60, a cart-pole other than the default one, the task
    the options name) and its Params; ParamError with one line for a value the checker sets."""
    if fixed := sorted(set(options) & set(FIXED)):
        raise ParamError(f"{fixed[0]} is the checker's own ({MAX_STEPS} steps, tau {TAU} s, "
                         f"the default force and limits, protocol paper, first_action infer)")
    return run_values({"max_steps": MAX_STEPS, **RUN_PHYSICS}, options=options)


def run_summary(run: Params) -> str:
    """'task cartpole: physics paper, ...' or 'task NAME, K actions': what the checker's run
    gives."""
    if run.task == CARTPOLE:
        return f"task {CARTPOLE}: {physics_summary(run)}"
    return f"task {run.task}, {run.n_actions} actions"


# --- the task description --------------------------------------------------------------------

def older_contract(namespace: str) -> str:
    """The one line for a node that publishes on cartpole/state and no env/task."""
    return f"the node speaks contract version 3 or older (it publishes " \
           f"{namespace.rstrip('/')}/{OLDER_STATE}, no {TASK}): docs/ENV_CONTRACT.md, " \
           f"\"Versions\", says what to change for version {ENV_CONTRACT_VERSION}"


def check_description(msg, run: Params) -> tuple[Described | None, list[str]]:
    """task: (the description as the graph reads it, or None where it cannot be read; what is
    wrong with it for the run)."""
    try:
        task = described(msg)
    except ParamError as error:
        return None, [f"the graph refuses its {TASK}: {error}"]
    problems = []
    if task.task.name != run.task:
        problems.append(f"{TASK} names task {task.task.name!r}, the run's is {run.task!r}")
    elif len(task.task.actions) != run.n_actions:
        problems.append(f"{TASK} has {len(task.task.actions)} actions, the run's n_actions is "
                        f"{run.n_actions}")
    if task.task.name == CARTPOLE:
        expected = Described(cartpole_task(run), CARTPOLE_TERMINATIONS).fields()
        got = task.fields()
        for name in ("variable_names", "variable_units", "variable_low", "variable_high",
                     "action_values", "ends_in", "termination_reasons"):
            if got[name] != expected[name]:
                problems.append(f"the cart-pole's {name} is {expected[name]}, not {got[name]}")
    return task, problems


# --- an observation --------------------------------------------------------------------------

def check_observation_of_the_tick(msg, tick: int, trial: int, after: str) -> Iterator[str]:
    """lockstep: the observation that answers `after` is that of `tick`, of the trial of the
    last START."""
    if msg.tick != tick:
        yield f"observation tick {msg.tick} after {after}"
    if msg.trial != trial:
        yield f"observation of tick {tick} has trial {msg.trial}, not {trial} (the trial of the " \
              f"last START)"


def check_observation(msg, task: Described, run: Params) -> Iterator[str]:
    """observation: what every subscriber refuses (graph.content), the task's count."""
    for problem in (observation_problem(msg, run), task.observation_problem(list(msg.values))):
        if problem:
            yield f"tick {msg.tick}: {problem}"


def check_termination(msg, task: Described) -> Iterator[str]:
    """termination: a reason of the task's, given only with terminated; the cart-pole's
    terminated exactly when it lies beyond a limit, with that limit's reason (the angle
    first)."""
    reasons = task.termination_reasons
    if msg.termination > len(reasons):
        yield f"tick {msg.tick}: termination {msg.termination}, the task names " \
              f"{len(reasons)} reasons ({', '.join(reasons) or 'none'}): 0 or 1 + an index"
    elif msg.termination and not msg.terminated:
        yield f"tick {msg.tick}: termination {msg.termination} " \
              f"({reasons[msg.termination - 1]}) without terminated"
    if task.task.name != CARTPOLE or len(msg.values) != 4:
        return
    x, _, angle, _ = msg.values
    beyond = 1 if abs(angle) > ANGLE_LIMIT_DEG else 2 if abs(x) > TRACK_LIMIT_M else 0
    where = f"angle {angle:.3f} deg, x {x:.3f} m"
    if msg.terminated and not beyond:
        yield f"tick {msg.tick}: terminated inside the limits ({where})"
    elif beyond and (not msg.terminated or msg.termination != beyond):
        yield f"tick {msg.tick}: beyond the {CARTPOLE_TERMINATIONS[beyond - 1]} limit " \
              f"({where}): terminated {msg.terminated}, termination {msg.termination}, " \
              f"expected terminated with termination {beyond}"


def check_reset(msg, angle: float | None, steps_before: int) -> Iterator[str]:
    """reset: the observation after START: no step counted, none of a step's outcome; the
    cart-pole (`angle` given): the cart at 0 and at rest, the pole at rest at `angle`."""
    if msg.successful_steps != 0:
        yield f"successful_steps not reset at START (was {steps_before}, published " \
              f"{msg.successful_steps})"
    if msg.reward != 0.0 or msg.terminated or msg.truncated or msg.termination:
        yield f"the observation after START is a step's (reward {msg.reward:g}, terminated " \
              f"{msg.terminated}, truncated {msg.truncated}, termination {msg.termination}): " \
              f"reward 0, neither terminated nor truncated"
    if angle is None or len(msg.values) != 4:
        return
    x, x_dot, theta, theta_dot = msg.values
    if x != 0.0 or x_dot != 0.0:
        yield f"cart not at 0 and at rest after START (x {x:g} m, dx/dt {x_dot:g})"
    if abs(theta - angle) > 1e-9 or theta_dot != 0.0:
        yield f"pole not at rest at START's initial_angle_deg {angle:g} (angle {theta:g} deg, " \
              f"rate {theta_dot:g} deg/s)"


def check_step_counted(msg, steps_before: int) -> Iterator[str]:
    """successful_steps: one more than before for a step that did not terminate, none for the
    terminating one."""
    expected = steps_before + (not msg.terminated)
    if msg.successful_steps != expected:
        what = "counts the terminating step" if msg.terminated and \
            msg.successful_steps == steps_before + 1 else f"expected {expected}"
        yield f"successful_steps {msg.successful_steps} at tick {msg.tick} of trial " \
              f"{msg.trial}: {what}"


def check_truncation(msg, task: Described) -> Iterator[str]:
    """truncation: truncated when successful_steps reaches max_steps (or the task's own
    max_steps, where it has one), never before, never past it."""
    cap = min(MAX_STEPS, task.task.max_steps or MAX_STEPS)
    if msg.successful_steps > cap:
        yield f"successful_steps {msg.successful_steps} passed max_steps {cap}"
    elif msg.truncated and msg.successful_steps < cap and not msg.terminated:
        yield f"truncated at tick {msg.tick} after {msg.successful_steps} successful steps, " \
              f"before max_steps {cap}"
    elif msg.successful_steps == cap and not (msg.truncated or msg.terminated):
        yield f"not truncated at tick {msg.tick}: successful_steps reached max_steps {cap}"


def check_one_observation_per_tick(observations) -> Iterator[str]:
    """lockstep: no tick has two observations."""
    seen = {}
    for msg in observations:
        seen[msg.tick] = seen.get(msg.tick, 0) + 1
    for tick, count in sorted(seen.items()):
        if count > 1:
            yield f"publishes {count} observations for tick {tick}"


# --- the cart-pole's physics -----------------------------------------------------------------

def check_physics(steps, run: Params = CHECKED_RUN) -> Iterator[str]:
    """physics: each step (the state before, the force direction, the state after, its tick)
    is one step of the core's cart-pole (clnn_ros.core.physics) with the run's parameters; a
    problem names the first step that differs, and what the node seems to step instead."""
    wrong = [step for step in steps if not follows(step, run)]
    if not wrong:
        return
    before, direction, after, tick = wrong[0]
    expected = expected_state(before, direction, run)
    shown = ", ".join(f"{name} {got:.9g} (expected {want:.9g})" for name, got, want in zip(
        ("x", "dx/dt", "angle", "rate"), after, expected) if not close(got, want))
    guess = next((what for what, other in other_physics(run)
                  if all(follows(step, other) for step in steps)), None)
    instead = f"; it steps {guess}" if guess else ""
    yield f"{len(wrong)} of {len(steps)} steps do not follow the run's cart-pole " \
          f"({physics_summary(run)}): tick {tick}, {'+' if direction > 0 else '-'}F: " \
          f"{shown}{instead}"


def physics_summary(run: Params) -> str:
    """'physics paper, semi_implicit, cart_mass 0.9 kg, ...': what the checker's run gives."""
    return ", ".join([f"physics {run.physics}", run.integrator,
                      *(f"{name} {getattr(run, name):g} {UNITS[name]}" for name in RUN_PHYSICS)])


def expected_state(before, direction: int, run: Params) -> tuple:
    """The state after `before` (degrees, as messages carry it) under the run's physics."""
    radians = state_in_radians(run)
    start = start_in_units(before, False, radians)
    return in_degrees(*physics_step(*start, direction * run.force, physics_constants(run),
                                    radians)[:4], radians)


def close(got: float, want: float) -> bool:
    return math.isclose(got, want, rel_tol=PHYSICS_TOLERANCE[0], abs_tol=PHYSICS_TOLERANCE[1])


def follows(step, run: Params) -> bool:
    before, direction, after, _ = step
    return all(close(got, want) for got, want in zip(after, expected_state(before, direction,
                                                                           run)))


def other_physics(run: Params) -> Iterator[tuple[str, Params]]:
    """(what, the Params) of what a node may step instead of the run's cart-pole: a parameter of
    the run's file ignored (its default kept), all of them, another physics or integrator."""
    default = Params()
    for name in RUN_PHYSICS:
        yield f"{name} {getattr(default, name):g} {UNITS[name]} (the default), not the " \
              f"run's {getattr(run, name):g}", run.replace(**{name: getattr(default, name)})
    yield "the default cart-pole (it ignores the run's physics parameters)", \
        run.replace(**{name: getattr(default, name) for name in RUN_PHYSICS})
    for physics in PHYSICS:
        for integrator in INTEGRATORS:
            if (physics, integrator) != (run.physics, run.integrator):
                yield f"physics {physics}, integrator {integrator}, not the run's " \
                      f"{run.physics}, {run.integrator}", \
                    run.replace(physics=physics, integrator=integrator)
