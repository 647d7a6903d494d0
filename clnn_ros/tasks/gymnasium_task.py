"""Any registered Gymnasium environment as a task (core.task.Task) and an environment
(core.task_episode.TaskEnvironment): `gymnasium:ID`, e.g. gymnasium:Acrobot-v1.

Its Task comes from its spaces and spec: a Box observation (its components named from the
table below where the task is known, x0, x1, ... elsewhere), its actions (a Discrete space's
every index; a Box space of shape (1,): a declared set of values, e.g. -3,3), its truncation
(spec.max_episode_steps) and its threshold (spec.reward_threshold). Its steps are its own:
reset(seed=...) and step(), through gymnasium.make, wrappers and all.

KNOWN gives the tasks the field measures on (issue 46's five and CartPole-v1) their names,
units, how their episodes end, and a first encoding (DEFAULTS): a starting point to run them,
not tuned on any seed; a preset per task is the next step.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..core.episode import STARTS_SEED
from ..core.params import ParamError, Params
from ..core.task import Action, Task, Variable

PREFIX = "gymnasium:"


@dataclass(frozen=True)
class Known:
    variables: tuple[tuple[str, str], ...]  # (name, unit) of each observation component
    ends_in: str = "failure"
    actions: str = ""  # the declared values of a Box action space, e.g. "-1,1"
    defaults: tuple[tuple[str, str], ...] = ()  # Params values (text) of a first encoding


KNOWN = {
    # gymnasium/envs/classic_control/cartpole.py names its state x, x_dot, theta, theta_dot
    "CartPole-v1": Known(
        (("x", "m"), ("x_dot", "m/s"), ("theta", "rad"), ("theta_dot", "rad/s")),
        defaults=(("state_vars", "theta,theta_dot,x_dot"),
                  ("variable_edges", "x:-0.8,0.8;x_dot:-0.2,0.2;theta:0;"
                                     "theta_dot:-0.17453292519943295,0.17453292519943295"))),
    "Acrobot-v1": Known(
        (("cos_theta1", ""), ("sin_theta1", ""), ("cos_theta2", ""), ("sin_theta2", ""),
         ("theta1_dot", "rad/s"), ("theta2_dot", "rad/s")), ends_in="success",
        defaults=(("variable_edges", "cos_theta1:0;sin_theta1:0;cos_theta2:0;sin_theta2:0;"
                                     "theta1_dot:-1,0,1;theta2_dot:-1,0,1"),)),
    "MountainCar-v0": Known(
        (("position", "m"), ("velocity", "m/s")), ends_in="success",
        defaults=(("variable_edges", "position:-0.9,-0.6,-0.3,0,0.3;velocity:-0.01,0,0.01"),)),
    "LunarLander-v3": Known(
        (("x", ""), ("y", ""), ("x_dot", ""), ("y_dot", ""), ("angle", "rad"),
         ("angular_velocity", ""), ("left_leg_contact", ""), ("right_leg_contact", "")),
        defaults=(("variable_edges", "x:-0.2,0.2;y:0.5;x_dot:-0.2,0.2;y_dot:-0.3,0;"
                                     "angle:-0.1,0.1;angular_velocity:-0.1,0.1;"
                                     "left_leg_contact:0.5;right_leg_contact:0.5"),)),
    # MuJoCo's joints: the cart on its slider, the pole on its hinge
    "InvertedPendulum-v5": Known(
        (("slider_position", "m"), ("hinge_angle", "rad"), ("slider_velocity", "m/s"),
         ("hinge_angular_velocity", "rad/s")), actions="-1,1",
        defaults=(("variable_edges", "slider_position:-0.5,0.5;hinge_angle:0;"
                                     "slider_velocity:-0.2,0.2;hinge_angular_velocity:-0.2,0.2"),
                  ("sigma", "16"), ("omega", "32"))),
    "InvertedDoublePendulum-v5": Known(
        (("slider_position", "m"), ("sin_hinge", ""), ("sin_hinge2", ""), ("cos_hinge", ""),
         ("cos_hinge2", ""), ("slider_velocity", "m/s"), ("hinge_angular_velocity", "rad/s"),
         ("hinge2_angular_velocity", "rad/s"), ("constraint_force", "")), actions="-1,0,1",
        defaults=(("state_vars", "slider_position,sin_hinge,sin_hinge2,hinge_angular_velocity,"
                                 "hinge2_angular_velocity"),
                  ("variable_edges", "slider_position:0;sin_hinge:-0.05,0,0.05;"
                                     "sin_hinge2:-0.05,0,0.05;hinge_angular_velocity:0;"
                                     "hinge2_angular_velocity:0"),
                  ("sigma", "16"), ("omega", "32"))),
}


def env_id(task_name: str) -> str:
    """The Gymnasium ID of a task name `gymnasium:ID`; ParamError for another name."""
    if not task_name.startswith(PREFIX) or not task_name[len(PREFIX):]:
        raise ParamError(f"a Gymnasium task is named {PREFIX}ID (e.g. {PREFIX}Acrobot-v1), "
                         f"got {task_name!r}")
    return task_name[len(PREFIX):]


class GymnasiumEnvironment:
    """A Gymnasium environment with actions numbered 0..K-1 (core.task_episode's interface);
    an observation that is not K finite numbers of the task's length is refused in one line."""

    def __init__(self, task: Task, env):
        self.task, self.env = task, env
        discrete = hasattr(env.action_space, "n")
        self._given = [int(env.action_space.start) + k if discrete
                       else np.array([a.value], dtype=env.action_space.dtype)
                       for k, a in enumerate(task.actions)]

    def reset(self, seed: int | None) -> np.ndarray:
        return self._checked(self.env.reset(seed=seed)[0])

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool]:
        observation, reward, terminated, truncated, _ = self.env.step(self._given[action])
        return self._checked(observation), float(reward), bool(terminated), bool(truncated)

    def _checked(self, observation) -> np.ndarray:
        values = np.asarray(observation, dtype=np.float64).ravel()
        if values.shape != (len(self.task.variables),) or not np.all(np.isfinite(values)):
            raise ParamError(f"{self.task.name}: an observation must be "
                             f"{len(self.task.variables)} finite numbers, got {values.tolist()}")
        return values


def make(task_name: str, actions: str | None = None) -> tuple[Task, GymnasiumEnvironment]:
    """The Task and a new environment of `gymnasium:ID`; `actions`: the declared values of a
    Box action space (text "-3,3"; a known task's default where not given). ParamError with one
    line for an ID Gymnasium lacks, a space this learner cannot take, or bad actions."""
    identifier = env_id(task_name)
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")  # box2d's import would print
    import gymnasium  # imported here: the rest of the project does not need it

    try:
        env = gymnasium.make(identifier)
    except gymnasium.error.Error as error:
        raise ParamError(f"{task_name}: {str(error).splitlines()[0]}") from None
    except ImportError as error:
        raise ParamError(f"{task_name}: Gymnasium cannot make it here ({error})") from None
    known = KNOWN.get(identifier)
    observation, action = env.observation_space, env.action_space
    if not isinstance(observation, gymnasium.spaces.Box) or len(observation.shape) != 1:
        raise ParamError(f"{task_name}: its observation space is {observation}, not a 1-D Box: "
                         f"the encoder needs named real values")
    names = known.variables if known else tuple((f"x{i}", "") for i in range(observation.shape[0]))
    if len(names) != observation.shape[0]:
        raise ParamError(f"{task_name}: {observation.shape[0]} observation components, "
                         f"{len(names)} names known for it")
    variables = tuple(Variable(name, unit, float(lo), float(hi))
                      for (name, unit), lo, hi in zip(names, observation.low, observation.high))
    spec = env.spec
    task = Task(task_name, variables, task_actions(task_name, action, actions, known),
                spec.max_episode_steps, spec.reward_threshold,
                known.ends_in if known else "failure")
    return task, GymnasiumEnvironment(task, env)


def task_actions(task_name: str, space, declared: str | None, known: Known | None):
    """The Task's actions of an action space: a Discrete one's every index, or the declared
    values of a Box one of shape (1,)."""
    import gymnasium

    if isinstance(space, gymnasium.spaces.Discrete):
        if declared:
            raise ParamError(f"{task_name}: its actions are Discrete({space.n}); --actions "
                             f"declares values of a Box action space only")
        return tuple(Action(str(k), float(space.start + k)) for k in range(space.n))
    if not isinstance(space, gymnasium.spaces.Box) or space.shape != (1,):
        raise ParamError(f"{task_name}: its action space is {space}: this learner takes a "
                         f"Discrete one, or a Box of shape (1,) with declared values")
    text = declared or (known.actions if known else "")
    if not text:
        raise ParamError(f"{task_name}: its action space is {space}: declare the values the "
                         f"agent may apply, e.g. --actions {space.low[0]:g},{space.high[0]:g}")
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise ParamError(f"{task_name}: --actions must be numbers separated by commas, "
                         f"got {text!r}") from None
    low, high = float(space.low[0]), float(space.high[0])
    if len(values) < 2 or len(set(values)) != len(values) or \
            not all(math.isfinite(v) and low <= v <= high for v in values):
        raise ParamError(f"{task_name}: --actions must be 2 or more distinct values in "
                         f"[{low:g}, {high:g}], got {text!r}")
    return tuple(Action(f"{v:g}", v) for v in values)


def task_params(task: Task, values: dict[str, str] | None = None,
                base: Params | None = None) -> Params:
    """The Params of a Gymnasium task (Task.params): the known task's first encoding, then
    `values` (text, as a command's options give them), over `base` made the task's."""
    known = KNOWN.get(env_id(task.name))
    return task.params({**dict(known.defaults if known else ()), **(values or {})}, base)


# The families whose step() never draws from the environment's random stream (read in
# Gymnasium's source; tests/test_checkpoint.py checks each known task): there, the stream at a
# trial's start depends on the resets before it alone. LunarLander-v3's steps draw (its engines'
# dispersion), so its trial k starts from a stream that its steps moved.
RESETS_ALONE_DRAW = ("gymnasium.envs.classic_control", "gymnasium.envs.mujoco")


def check_resumable(task_name: str) -> None:
    """ParamError with one line unless an episode of `task_name` can resume at any trial: its
    trial k starts where k resets after the seeded one put the environment's random stream."""
    import gymnasium  # imported here: the rest of the project does not need it

    spec = gymnasium.spec(env_id(task_name))
    entry_point = spec.entry_point if isinstance(spec.entry_point, str) else \
        f"{spec.entry_point.__module__}:"
    if not entry_point.startswith(RESETS_ALONE_DRAW):
        raise ParamError(f"{task_name} cannot resume from a checkpoint: its steps may draw from "
                         f"its random stream ({entry_point.split(':')[0]}), so a later trial's "
                         f"start cannot be made again from the seed")


class GymnasiumTaskEnvironment:
    """A Gymnasium task as an environment node runs it (tasks.cartpole.CartPoleEnvironment's
    calls): trial 0 of seed s resets with seed STARTS_SEED + s, every later trial with None, as
    core.task_episode does; no named terminations. A resumed episode's first trial k > 0 makes
    the k resets before it again (check_resumable: where that gives the same start)."""

    termination_reasons = ()

    def __init__(self, params: Params, actions: str = ""):
        self.task, self.env = make(params.task, actions or None)
        if params.n_actions != len(self.task.actions):  # what it encodes is not its business
            raise ParamError(f"task {self.task.name} has {len(self.task.actions)} actions "
                             f"({', '.join(self.task.action_labels)}); n_actions is "
                             f"{params.n_actions}")
        self._next_draw = None  # (seed, trial) whose start the environment's next reset() draws

    def start(self, seed: int, trial: int, _initial_angle_deg: float) -> np.ndarray:
        if (seed, trial) == self._next_draw:
            observation = self.env.reset(None)
        else:  # a new episode, or a resumed one: its seeded reset and one more per trial before
            if trial > 0:
                check_resumable(self.task.name)
            observation = self.env.reset(STARTS_SEED + seed)
            for _ in range(trial):
                observation = self.env.reset(None)
        self._next_draw = (seed, trial + 1)
        return observation

    def step(self, action: int) -> tuple:
        return (*self.env.step(action), 0)


def graph_defaults(environment: str, defaults: dict, actions: str | None) -> dict:
    """A graph run's defaults for its environment (run_all's --env, the launch's env:=):
    `defaults` (the demonstration's), with a Gymnasium task's own values (run_values) over them
    but the cart-pole's nsv; ParamError with one line for actions without such a task."""
    if environment.startswith(PREFIX):
        return {**{k: v for k, v in defaults.items() if k != "nsv"},
                **run_values(environment, actions)}
    if actions is not None:
        raise ParamError(f"actions ({actions}) declares the values of a Gymnasium task's Box "
                         f"action space ({PREFIX}ID), not of {environment}")
    return defaults


def run_values(task_name: str, actions: str | None = None) -> dict:
    """The values of a graph run of `gymnasium:ID` (its parameters' layer under the user's):
    the task's name, its actions, truncation and reward mapping, every variable encoded, and
    the known task's first encoding (an unknown task's edges are the user's to give: the run's
    check says so); ParamError as make()."""
    task, _ = make(task_name, actions)
    values = {"max_steps": Params().max_steps, **task.own_values(),
              "state_vars": ",".join(task.names)}
    known = KNOWN.get(env_id(task_name))
    return {**values, **dict(known.defaults if known else ()), "actions": actions or ""}
