"""The tasks whose step is compiled, behind one interface for the task batch engine
(clnn_ros.task_batch): a trial's start, a step and the observation, chosen by the task's code.
Each task's step lives in its own room (classic_control: Acrobot-v1, MountainCar-v0;
mujoco_control: InvertedPendulum-v5, InvertedDoublePendulum-v5); a task compiled anew adds its
code and three branches here.

A task's state is a float64 array: the classic tasks' own state, stepped in place; a MuJoCo
task's start (qpos then qvel), its state proper living in `sim`, the MuJoCo data the steps
advance (empty arrays for the classic tasks).
"""

from __future__ import annotations

import numba
import numpy as np

from ..core.task import Task
from . import classic_control, mujoco_control
from .gymnasium_task import env_id

ACROBOT, MOUNTAIN_CAR, INVERTED_PENDULUM, INVERTED_DOUBLE_PENDULUM = 0, 1, 2, 3
COMPILED = {"Acrobot-v1": ACROBOT, "MountainCar-v0": MOUNTAIN_CAR,
            "InvertedPendulum-v5": INVERTED_PENDULUM,
            "InvertedDoublePendulum-v5": INVERTED_DOUBLE_PENDULUM}  # Gymnasium ID -> code
MUJOCO = (INVERTED_PENDULUM, INVERTED_DOUBLE_PENDULUM)


class CompiledTask:
    """What the compiled functions take of a compiled task and a Gymnasium environment `env`
    of it: its code, `sim` (for a MuJoCo task a simulation of the environment's model, its
    handles and data arrays) and `forces`, each action's control as the environment receives
    it (a Box action space's values in its dtype; a Discrete one's go unused)."""

    def __init__(self, task: Task, env):
        self.code = COMPILED[env_id(task.name)]
        if self.code in MUJOCO:
            self._simulation = mujoco_control.Simulation(env.unwrapped.model)
            self.sim = (self._simulation.handles, *self._simulation.arrays)
        else:  # (handles, ctrl, qpos, qvel, site_xpos, qfrc_constraint): one type for every task
            nothing = np.empty(0)
            self.sim = (np.zeros(2, dtype=np.int64), *[nothing] * 5)
        # the value in the action space's dtype (float32 for MuJoCo), then float64 as ctrl is
        self.forces = np.array([np.asarray(a.value, dtype=env.action_space.dtype)
                                for a in task.actions], dtype=np.float64)

    def start_state(self, env) -> np.ndarray:
        """The state of `env` just after its reset."""
        if self.code in MUJOCO:
            return mujoco_control.start_state(env)
        return classic_control.start_state(env)


@numba.njit(cache=True)
def begin(task, state, sim):
    """A trial's start from `state`, as the environment's reset left it."""
    if task == INVERTED_PENDULUM or task == INVERTED_DOUBLE_PENDULUM:
        mujoco_control.begin(sim[0], sim[2], sim[3], state)


@numba.njit(cache=True)
def step(task, state, sim, forces, action):
    """The step of action index `action`: (reward, terminated)."""
    if task == ACROBOT:
        return classic_control.acrobot_step(state, action)
    if task == MOUNTAIN_CAR:
        return classic_control.mountain_car_step(state, action)
    if task == INVERTED_PENDULUM:
        return mujoco_control.inverted_pendulum_step(sim[0], sim[1], sim[2], sim[3],
                                                     forces[action])
    return mujoco_control.inverted_double_pendulum_step(sim[0], sim[1], sim[3], sim[4],
                                                        forces[action])


@numba.njit(cache=True)
def observe(task, state, sim, out):
    """The observation, as the environment returns it, into `out`."""
    if task == ACROBOT:
        classic_control.acrobot_observe(state, out)
    elif task == MOUNTAIN_CAR:
        classic_control.mountain_car_observe(state, out)
    elif task == INVERTED_PENDULUM:
        mujoco_control.observe(sim[2], sim[3], out)
    else:
        mujoco_control.observe_double(sim[2], sim[3], sim[5], out)
