"""The MuJoCo cart-pole (clnn_ros/tasks/cartpole/mujoco_cartpole.py, the environment node with simulator:=mujoco): the
plant's sign conventions and geometry, its agreement with the core's physics with the same
constants, the contract checker on its node, and a `run_all --env mujoco` run equal to the core
driving the same plant (docs/MUJOCO.md)."""

from __future__ import annotations

import math
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from clnn_ros.live.check_env import RULES
from clnn_ros.core.episode import run_episode
from clnn_ros.core.physics import gym_matched_params
from clnn_ros.tasks.cartpole.mujoco_cartpole import MujocoCartPole
from clnn_ros.core.params import Params, params_from_strings
from clnn_ros.core.physics import CONTINUE, FAIL_ANGLE, FAIL_POSITION, CartPole, at_rest
from clnn_ros.core.presets import preset_values

from conftest import assert_run_equals_episode, free_domain_id, ros_environment

PY = sys.executable
DOMAIN_ID = free_domain_id()
# The plant against the core's `correct` physics with `semi_implicit` integration (the same
# discrete model) over this test's 20 random actions: measured at most 6e-14 (theta_dot, deg/s),
# rounding grown by the pole's instability (x53 a second). The same comparison with an error in
# the model: gravity 9.81, 1e-2; pole mass 0.101 kg, 0.4; the rod's inertia about its end
# instead of its centre, 68. 1e-9 lies far from both sides (docs/MUJOCO.md: other sequences).
AGREEMENT_STEPS = 20
AGREEMENT_TOLERANCE = 1e-9


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)


def test_a_positive_angle_leans_the_pole_toward_plus_x_and_it_falls_that_way():
    plant = MujocoCartPole()
    plant.reset(at_rest(1.0))
    assert plant.state == pytest.approx((0.0, 0.0, 1.0, 0.0))
    mujoco.mj_kinematics(plant.model, plant.data)
    pole_centre = plant.data.xipos[plant.model.body("pole").id]
    assert pole_centre[0] == pytest.approx(0.5 * math.sin(math.radians(1.0)))
    assert pole_centre[2] == pytest.approx(0.5 * math.cos(math.radians(1.0)))
    plant.data.ctrl[0] = 0.0  # no force: gravity alone
    mujoco.mj_step(plant.model, plant.data)
    _, theta_dot = plant.data.qvel
    assert theta_dot > 0


@pytest.mark.parametrize("action, cart_direction", [(1, +1), (0, -1)])
def test_plus_force_pushes_the_cart_toward_plus_x_and_turns_the_pole_back(action,
                                                                          cart_direction):
    """As in core/physics.py: +F (action 1) pushes toward +x and makes theta_acc negative."""
    plant = MujocoCartPole()
    plant.reset(at_rest(0.0))
    assert plant.step(action) == CONTINUE
    x, x_dot, theta_deg, theta_dot_deg = plant.state
    assert np.sign(x) == np.sign(x_dot) == cart_direction
    assert np.sign(theta_deg) == np.sign(theta_dot_deg) == -cart_direction


def test_the_plant_follows_the_core_physics_with_the_same_constants():
    actions = np.random.default_rng(0).integers(0, 2, AGREEMENT_STEPS)
    plant = MujocoCartPole()
    core = CartPole(gym_matched_params(Params()).replace(integrator="semi_implicit"))
    plant.reset(at_rest(1.0))
    core.reset(at_rest(1.0))
    for action in actions:
        assert plant.step(action) == core.step(action)
        np.testing.assert_allclose(plant.state, core.state, rtol=0, atol=AGREEMENT_TOLERANCE)


def test_limits_are_checked_after_each_step_the_angle_first():
    plant = MujocoCartPole()
    plant.reset(at_rest(11.9))
    assert plant.step(0) == FAIL_ANGLE  # -F tips the pole further toward +theta
    for angle_deg, expected in ((0.0, FAIL_POSITION), (11.9, FAIL_ANGLE)):
        plant.reset(at_rest(angle_deg))
        plant.data.qpos[0], plant.data.qvel[0] = 2.39, 1.0  # the cart about to leave the track
        assert plant.step(0) == expected


@pytest.mark.ros
def test_contract_checker_passes_the_mujoco_node(ros_env):
    result = subprocess.run(
        [PY, "-m", "clnn_ros.live.check_env", "--domain-id", DOMAIN_ID, "--namespace",
         "/check_mujoco", PY, "-m", "clnn_ros.nodes.environment", "--ros-args", "-p",
         "simulator:=mujoco"],
        env=ros_env, capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stdout
    assert sum(line.startswith("PASS  ") for line in result.stdout.splitlines()) == len(RULES), \
        result.stdout


@pytest.mark.ros
def test_mujoco_node_run_equals_core_on_the_mujoco_plant(ros_env, tmp_path):
    seed, trials, max_steps = 1, 4, 200
    result = subprocess.run(
        [PY, "-m", "clnn_ros.run_all", "--quiet", "--no-record", "--namespace", "mujoco",
         "--env", "mujoco", "--preset", "gymnasium", "--seed", str(seed), "--trials",
         str(trials), "--max-steps", str(max_steps), "--out", str(tmp_path)],
        env=ros_env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "environment: mujoco" in result.stdout
    p = params_from_strings(preset_values("gymnasium")).replace(trials=trials,
                                                                max_steps=max_steps)
    assert_run_equals_episode(tmp_path, run_episode(seed, p, env_factory=MujocoCartPole))
