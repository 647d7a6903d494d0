"""Gymnasium's InvertedPendulum-v5 and InvertedDoublePendulum-v5 steps compiled: the same
numbers as Gymnasium's own `step()`, bit for bit (tests/test_task_batch.py), for the task batch
engine (clnn_ros.task_batch).

The physics is MuJoCo's own: numba calls the C functions of the libmujoco that the `mujoco`
package loaded (mj_step, mj_forward, ...) on an MjModel and MjData of the task, as Gymnasium's
MujocoEnv does through the Python bindings; what is ported is only the few lines around them
(inverted_pendulum_v5.py and inverted_double_pendulum_v5.py: the control set, frame_skip steps,
mj_rnePostConstraint, the observation in float64, the reward and the termination). What is
gained is Python's part of a step (about two thirds of it for InvertedPendulum-v5); MuJoCo's own
part remains.

A trial starts as MujocoEnv.reset leaves the data after its draw: mj_resetData (time, warm start
and all to their defaults), the drawn qpos and qvel, mj_forward. The draw is Gymnasium's own
(its reset), so the starts are taken from it.
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import llvmlite.binding as llvm
import mujoco
import numba
import numpy as np
from numba import types

from . import classic_control

FRAME_SKIP = 2  # InvertedPendulum-v5's frame_skip: two MuJoCo steps of 0.02 s per step
MAX_ANGLE = 0.2  # rad: the hinge beyond it terminates
DOUBLE_FRAME_SKIP = 5  # InvertedDoublePendulum-v5's: five MuJoCo steps of 0.01 s
HEALTHY_REWARD = 10.0  # InvertedDoublePendulum-v5's healthy_reward (its default)
MIN_TIP_HEIGHT = 1.0  # m: the tip's site at or below it terminates
CLIP = 10.0  # InvertedDoublePendulum-v5 clips qvel and qfrc_constraint to +-10 in its observation

# The C functions under names of this project's own (llvm.add_symbol), so that the compiled code
# keeps no address of this process and numba can cache it, as classic_control does libm's pow.
_library = ctypes.CDLL(str(next(Path(mujoco.__file__).parent.glob("libmujoco.so*"))))
for _name in ("mj_step", "mj_forward", "mj_resetData", "mj_rnePostConstraint"):
    llvm.add_symbol(f"clnn_ros_{_name}",
                    ctypes.cast(getattr(_library, _name), ctypes.c_void_p).value)
_MODEL_DATA = types.void(types.intp, types.intp)  # (const mjModel*, mjData*), as addresses
_mj_step = types.ExternalFunction("clnn_ros_mj_step", _MODEL_DATA)
_mj_forward = types.ExternalFunction("clnn_ros_mj_forward", _MODEL_DATA)
_mj_reset_data = types.ExternalFunction("clnn_ros_mj_resetData", _MODEL_DATA)
_mj_rne_post_constraint = types.ExternalFunction("clnn_ros_mj_rnePostConstraint", _MODEL_DATA)


class Simulation:
    """A MuJoCo model with data of its own for the compiled steps: `handles` its model's and
    data's addresses, and `arrays`, the data's arrays the steps read and write (views of its
    memory): ctrl, qpos, qvel, site_xpos (flat) and qfrc_constraint."""

    def __init__(self, model: mujoco.MjModel):
        self.model, self.data = model, mujoco.MjData(model)  # held: the addresses stay valid
        self.handles = np.array([model._address, self.data._address], dtype=np.int64)
        d = self.data
        # site_xpos is C-ordered (nsite, 3): reshape gives a view, which the steps see move
        self.arrays = (d.ctrl, d.qpos, d.qvel, d.site_xpos.reshape(-1), d.qfrc_constraint)


def start_state(env) -> np.ndarray:
    """qpos then qvel of a Gymnasium MuJoCo environment just after its reset."""
    data = env.unwrapped.data
    return np.concatenate([data.qpos, data.qvel]).astype(np.float64)


@numba.njit(cache=True)
def begin(handles, qpos, qvel, start):
    """The data as MujocoEnv.reset leaves it with qpos and qvel `start`."""
    _mj_reset_data(handles[0], handles[1])
    qpos[:] = start[:qpos.shape[0]]
    qvel[:] = start[qpos.shape[0]:]
    _mj_forward(handles[0], handles[1])


@numba.njit(cache=True)
def _advance(handles, ctrl, force, frame_skip):
    """MujocoEnv.do_simulation: the control set, frame_skip MuJoCo steps, mj_rnePostConstraint."""
    ctrl[0] = force
    for _ in range(frame_skip):
        _mj_step(handles[0], handles[1])
    _mj_rne_post_constraint(handles[0], handles[1])


@numba.njit(cache=True)
def inverted_pendulum_step(handles, ctrl, qpos, qvel, force):
    """InvertedPendulumEnv.step with the control `force` (as the float32 action gives it):
    (reward, terminated)."""
    _advance(handles, ctrl, force, FRAME_SKIP)
    finite = (math.isfinite(qpos[0]) and math.isfinite(qpos[1]) and math.isfinite(qvel[0])
              and math.isfinite(qvel[1]))
    terminated = not finite or abs(qpos[1]) > MAX_ANGLE
    return (0.0 if terminated else 1.0), terminated


@numba.njit(cache=True)
def observe(qpos, qvel, out):
    """The observation of a MuJoCo task that observes qpos then qvel (InvertedPendulum-v5)."""
    out[:qpos.shape[0]] = qpos
    out[qpos.shape[0]:] = qvel


@numba.njit(cache=True)
def inverted_double_pendulum_step(handles, ctrl, qvel, site_xpos, force):
    """InvertedDoublePendulumEnv.step with the control `force`: (reward, terminated), the tip's
    site (site_xpos[0]) giving the distance penalty and the termination."""
    _advance(handles, ctrl, force, DOUBLE_FRAME_SKIP)
    x, y = site_xpos[0], site_xpos[2]
    terminated = y <= MIN_TIP_HEIGHT
    square = classic_control.square  # x ** 2 as NumPy computes it for a float64 scalar
    dist_penalty = 0.01 * square(x) + square(y - 2)
    vel_penalty = 1e-3 * square(qvel[1]) + 5e-3 * square(qvel[2])
    alive_bonus = 0.0 if terminated else HEALTHY_REWARD
    return alive_bonus - dist_penalty - vel_penalty, terminated


@numba.njit(cache=True)
def observe_double(qpos, qvel, qfrc_constraint, out):
    """InvertedDoublePendulum-v5's observation: the cart's position, the sines then the cosines
    of the two hinges' angles, the velocities and the cart's constraint force clipped to +-10."""
    out[0] = qpos[0]
    links = qpos.shape[0] - 1
    for i in range(links):
        out[1 + i] = math.sin(qpos[1 + i])
        out[1 + links + i] = math.cos(qpos[1 + i])
    at = 1 + 2 * links
    for i in range(qvel.shape[0]):
        out[at + i] = min(max(qvel[i], -CLIP), CLIP)
    out[at + qvel.shape[0]] = min(max(qfrc_constraint[0], -CLIP), CLIP)
