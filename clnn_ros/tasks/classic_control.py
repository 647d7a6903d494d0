"""Gymnasium's Acrobot-v1 and MountainCar-v0 steps, compiled: the same numbers as Gymnasium's
own `step()`, bit for bit (tests/test_task_batch.py), at a microsecond a step instead of 40-180
(Acrobot's Python RK4), for the task batch engine (clnn_ros.task_batch, through tasks.compiled).

Each is a port of gymnasium/envs/classic_control (acrobot.py, mountain_car.py, Gymnasium 1.x),
operation for operation in the same order, as core.physics's `gymnasium` step is of cartpole.py. Two things
keep the bits: Gymnasium squares NumPy scalars with `**`, which is libm's pow() (a square from
pow differs from x * x in about one case in a thousand here), so the port calls libm's pow too,
where numba would make x * x of it; and the observation is Gymnasium's float32 array, so the
values the encoder sees are the state rounded to float32.

A step writes the next state in place and returns (reward, terminated); `observe` writes the
observation. Neither draws on a random stream (Gymnasium's resets alone do: the engine takes
each trial's start from Gymnasium's own reset).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import math

import llvmlite.binding as llvm
import numba
import numpy as np
from numba import types

# libm's pow under a name LLVM does not know: under its own, LLVM would make pow(x, 2.0) x * x.
# Called by that name, the compiled code keeps no address of this process: numba can cache it.
llvm.add_symbol("clnn_ros_libm_pow", ctypes.cast(
    ctypes.CDLL(ctypes.util.find_library("m")).pow, ctypes.c_void_p).value)
_libm_pow = types.ExternalFunction("clnn_ros_libm_pow",
                                   types.float64(types.float64, types.float64))


@numba.njit(cache=True)
def square(x):
    """x ** 2 as NumPy computes it for a float64 scalar (libm's pow)."""
    return _libm_pow(x, 2.0)


# ---- Acrobot-v1 (acrobot.py: book dynamics, dt 0.2, RK4, no torque noise) ---------------------
_DT = 0.2
_PI = math.pi
_MAX_VEL_1, _MAX_VEL_2 = 4 * _PI, 9 * _PI
_TORQUE = (-1.0, 0.0, 1.0)


@numba.njit(cache=True)
def _acrobot_derivatives(s0, s1, s2, s3, a):
    """AcrobotEnv._dsdt (book), its masses, lengths and moments 1.0 and 0.5 as there."""
    m1 = m2 = l1 = I1 = I2 = 1.0
    lc1 = lc2 = 0.5
    g = 9.8
    theta1, theta2, dtheta1, dtheta2 = s0, s1, s2, s3
    d1 = m1 * lc1 ** 2 + m2 * (l1 ** 2 + lc2 ** 2 + 2 * l1 * lc2 * math.cos(theta2)) + I1 + I2
    d2 = m2 * (lc2 ** 2 + l1 * lc2 * math.cos(theta2)) + I2
    phi2 = m2 * lc2 * g * math.cos(theta1 + theta2 - _PI / 2.0)
    phi1 = (-m2 * l1 * lc2 * square(dtheta2) * math.sin(theta2)
            - 2 * m2 * l1 * lc2 * dtheta2 * dtheta1 * math.sin(theta2)
            + (m1 * lc1 + m2 * l1) * g * math.cos(theta1 - _PI / 2)
            + phi2)
    ddtheta2 = ((a + d2 / d1 * phi1 - m2 * l1 * lc2 * square(dtheta1) * math.sin(theta2) - phi2)
                / (m2 * lc2 ** 2 + I2 - square(d2) / d1))
    ddtheta1 = -(d2 * ddtheta2 + phi1) / d1
    return dtheta1, dtheta2, ddtheta1, ddtheta2


@numba.njit(cache=True)
def _wrap(x, m, big_m):
    diff = big_m - m
    while x > big_m:
        x = x - diff
    while x < m:
        x = x + diff
    return x


@numba.njit(cache=True)
def acrobot_step(state, action):
    """AcrobotEnv.step: one RK4 step of dt over [0, dt] (acrobot.rk4), the angles wrapped and
    the velocities bound. The torque's own derivative is 0, so it stays as it is."""
    a = _TORQUE[action]
    y0, y1, y2, y3 = state[0], state[1], state[2], state[3]
    dt = _DT - 0
    dt2 = dt / 2.0
    k1 = _acrobot_derivatives(y0, y1, y2, y3, a)
    k2 = _acrobot_derivatives(y0 + dt2 * k1[0], y1 + dt2 * k1[1], y2 + dt2 * k1[2],
                              y3 + dt2 * k1[3], a)
    k3 = _acrobot_derivatives(y0 + dt2 * k2[0], y1 + dt2 * k2[1], y2 + dt2 * k2[2],
                              y3 + dt2 * k2[3], a)
    k4 = _acrobot_derivatives(y0 + dt * k3[0], y1 + dt * k3[1], y2 + dt * k3[2],
                              y3 + dt * k3[3], a)
    for j in range(4):
        state[j] = state[j] + dt / 6.0 * (k1[j] + 2 * k2[j] + 2 * k3[j] + k4[j])
    state[0] = _wrap(state[0], -_PI, _PI)
    state[1] = _wrap(state[1], -_PI, _PI)
    state[2] = min(max(state[2], -_MAX_VEL_1), _MAX_VEL_1)
    state[3] = min(max(state[3], -_MAX_VEL_2), _MAX_VEL_2)
    terminated = -math.cos(state[0]) - math.cos(state[1] + state[0]) > 1.0
    return (0.0 if terminated else -1.0), terminated


@numba.njit(cache=True)
def acrobot_observe(state, out):
    out[0] = np.float32(math.cos(state[0]))
    out[1] = np.float32(math.sin(state[0]))
    out[2] = np.float32(math.cos(state[1]))
    out[3] = np.float32(math.sin(state[1]))
    out[4] = np.float32(state[2])
    out[5] = np.float32(state[3])


# ---- MountainCar-v0 (mountain_car.py) ----------------------------------------------------------
_MIN_POSITION, _MAX_POSITION, _MAX_SPEED = -1.2, 0.6, 0.07
_GOAL_POSITION, _GOAL_VELOCITY = 0.5, 0.0
_FORCE, _GRAVITY = 0.001, 0.0025


@numba.njit(cache=True)
def mountain_car_step(state, action):
    """MountainCarEnv.step."""
    position, velocity = state[0], state[1]
    velocity += (action - 1) * _FORCE + math.cos(3 * position) * (-_GRAVITY)
    velocity = min(max(velocity, -_MAX_SPEED), _MAX_SPEED)
    position += velocity
    position = min(max(position, _MIN_POSITION), _MAX_POSITION)
    if position == _MIN_POSITION and velocity < 0:
        velocity = 0.0
    state[0], state[1] = position, velocity
    return -1.0, position >= _GOAL_POSITION and velocity >= _GOAL_VELOCITY


@numba.njit(cache=True)
def mountain_car_observe(state, out):
    out[0] = np.float32(state[0])
    out[1] = np.float32(state[1])


def start_state(env) -> np.ndarray:
    """The state of a Gymnasium environment of these tasks just after its reset, float64."""
    return np.array(env.unwrapped.state, dtype=np.float64)
