"""Swapping the environment node: the contract checker passes the project's environment nodes
(paper cart-pole, gymnasium, the example) and fails broken ones with the right explanation; a
gymnasium-node run equals the core driving gymnasium's physics; the encoder edges are
parameters (docs/ENV_CONTRACT.md)."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clnn_ros.batch import run_batch
from clnn_ros.core.encoder import Encoder
from clnn_ros.core.episode import run_episode
from clnn_ros.core.gym_physics import GymCartPole, gym_matched_params
from clnn_ros.core.params import ParamError, Params, params_from_strings

ROOT = Path(__file__).resolve().parents[1]
BROKEN = str(Path(__file__).with_name("broken_env_node.py"))
PY = sys.executable
# name: (node command, checker options, lines the report must have)
CHECKS = {
    "cartpole": ([PY, "-m", "clnn_ros.nodes.environment", "--ros-args", "-p", "physics:=paper"],
                 [], ["check_env_node: all rules pass"]),
    "gymnasium": ([PY, "-m", "clnn_ros.nodes.gymnasium_env"], [],
                  ["check_env_node: all rules pass"]),
    "example": (["python", "examples/noisy_cartpole.py", "--ros-args", "-p", "force_noise:=0.2"],
                [], ["check_env_node: all rules pass"]),
    "no_reset": ([PY, BROKEN, "no_reset"], [],
                 ["FAIL  reset: successful_steps not reset at START (was 60, published 60)"]),
    "wrong_tick": ([PY, BROKEN, "wrong_tick"], [],
                   ["FAIL  lockstep: state tick 3 after action of tick 1", "PASS  reset"]),
    "several": ([PY, BROKEN, "no_exit,accept_bad_force,silent"], ["--startup-timeout", "3"],
                ["FAIL  readiness: no readiness announcement",
                 "FAIL  refusals: does not refuse an action with force_direction 5",
                 "FAIL  episode_end: does not exit on EPISODE_END", "PASS  lockstep",
                 "PASS  successful_steps", "PASS  failure"]),
}


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "ROS_LOG_DIR": str(tmp_path_factory.mktemp("ros_log"))}


@pytest.fixture(scope="module")
def checks(ros_env):
    """All checker runs at once, each in its own ROS domain (they mostly wait on the node)."""
    base = 160 + (os.getpid() % 8) * 8
    running = {name: subprocess.Popen(
        [PY, "-m", "clnn_ros.check_env_node", "--domain-id", str(base + i), *options, *command],
        cwd=ROOT, env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        for i, (name, (command, options, _)) in enumerate(CHECKS.items())}
    return {name: (p.communicate(timeout=120)[0], p.returncode) for name, p in running.items()}


@pytest.mark.parametrize("name", CHECKS)
def test_checker(checks, name):
    report, status = checks[name]
    assert status == (0 if name in ("cartpole", "gymnasium", "example") else 1), report
    lines = report.splitlines()
    for expected in CHECKS[name][2]:
        assert any(line.startswith(expected) for line in lines), report


def test_gymnasium_node_run_equals_core_on_gymnasium_physics(ros_env, tmp_path):
    trials, max_steps, seed = 12, 300, 1
    env = {**ros_env, "ROS_DOMAIN_ID": str(150 + os.getpid() % 8)}
    result = subprocess.run(
        [PY, "-m", "clnn_ros.run_all", "--quiet", "--env", "gymnasium", "--seed", str(seed),
         "--nsv", "2", "--velocity-edge", "0.3", "--trials", str(trials), "--max-steps",
         str(max_steps), "--out", str(tmp_path)], env=env, capture_output=True, text=True,
        timeout=120)
    assert result.returncode == 0, result.stderr
    p = Params(nsv=2, velocity_edge=0.3, trials=trials, max_steps=max_steps)
    core = run_episode(seed, p, env_factory=GymCartPole)
    with open(tmp_path / "trials.csv") as f:
        assert [int(r["steps"]) for r in csv.DictReader(f)] == core.steps.tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), core.final_weights)


def test_core_physics_with_gymnasium_constants_follows_gymnasium():
    """The core's own physics with gymnasium's masses (what the batch engine runs) gives the
    same trials as gymnasium's step on a short episode (long chaotic trials may drift apart)."""
    p = Params(nsv=2, velocity_edge=0.3, trials=16, max_steps=300)
    gym = run_episode(2, p, env_factory=GymCartPole)
    np.testing.assert_array_equal(run_episode(2, gym_matched_params(p)).steps, gym.steps)


def test_angle_edges_are_a_parameter():
    default = Params()
    assert default.angle_edges_deg == (-6.0, -1.0, 0.0, 1.0, 6.0) and default.n_inputs == 6
    p = params_from_strings({"angle_edges_deg": "-3, 0, 3", "nsv": "2"})
    assert p.angle_edges_deg == (-3.0, 0.0, 3.0) and p.n_inputs == 4 + 3
    assert params_from_strings({"angle_edges_deg": [-2, 2]}).angle_edges_deg == (-2.0, 2.0)
    assert params_from_strings({"angle_edges_deg": "[-2.5,2]"}).angle_edges_deg == (-2.5, 2.0)
    encoder = Encoder.from_params(p)
    assert encoder.labels()[:4] == ["pole_angle[-inf,-3)deg", "pole_angle[-3,0)deg",
                                    "pole_angle[0,3)deg", "pole_angle[3,inf)deg"]
    assert encoder.spikes((0.0, 6.0, 0.5, 0.0)).tolist() == [0, 0, 1, 0, 0, 0, 1]
    # the batch engine encodes with the same edges: equal to the core
    q = Params(angle_edges_deg="-4,-0.5,0,0.5,4", trials=24, max_steps=1500)
    assert run_batch([3], q).steps[0].tolist() == run_episode(3, q).steps.tolist()


@pytest.mark.parametrize("value, message", [
    ("1,0", "strictly increasing"), ("-1,-1", "strictly increasing"),
    ("-12,0", "inside [+]-angle_limit_deg"), ("0,15", "inside [+]-angle_limit_deg"),
    ("a,b", "numbers separated by commas"), ("", "one or more finite numbers"),
    ("nan", "one or more finite numbers"), ([True, 2], "numbers separated by commas"),
])
def test_bad_angle_edges(value, message):
    with pytest.raises(ParamError, match=message):
        params_from_strings({"angle_edges_deg": value})
    with pytest.raises(ParamError, match=message):
        Params(angle_edges_deg=value)


@pytest.mark.parametrize("args, message", [
    (["--env-node", "python x.py", "--composed"], "--env-node runs its own process"),
    (["--env-node", ""], "--env-node needs a command"),
    (["--env", "mujoco"], "invalid choice: 'mujoco'"),
    (["--env", "gymnasium", "--option", "tau=0.01"], "steps gymnasium's tau of 0.02 s"),
])
def test_run_all_environment_options_are_checked(ros_env, args, message):
    result = subprocess.run([PY, "-m", "clnn_ros.run_all", *args], env=ros_env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and message in result.stderr, result.stderr


def test_graph_encodes_other_angle_edges_from_parameters_only(ros_env, tmp_path):
    env = {**ros_env, "ROS_DOMAIN_ID": str(150 + os.getpid() % 8)}
    result = subprocess.run(
        [PY, "-m", "clnn_ros.run_all", "--quiet", "--no-record", "--option",
         "angle_edges_deg=-3,0,3", "--seed", "1", "--trials", "6", "--max-steps", "400",
         "--out", str(tmp_path)], env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    core = run_episode(1, Params(angle_edges_deg="-3,0,3", trials=6, max_steps=400))
    with open(tmp_path / "trials.csv") as f:
        assert [int(r["steps"]) for r in csv.DictReader(f)] == core.steps.tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), core.final_weights)
