"""Gymnasium's tasks through the real ROS 2 graph (contract version 4: env/observation, the
latched env/task, actions by index) against the core's task episode: the same trials and final
weights, one task of each family Gymnasium builds differently (classic control, Box2D, MuJoCo)."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clnn_ros.core.task_episode import run_task_episode
from clnn_ros.tasks.gymnasium_task import make, task_params

from conftest import free_domain_id, ros_environment

pytestmark = pytest.mark.ros
DOMAIN_ID = free_domain_id()
HANG_S = 600  # a bound against a hang, never a speed bound
UNKNOWN_TASK = "gymnasium:nan_task:NanObservation-v0"  # registered by tests/nan_task.py


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)


def run_all(env, *args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--quiet", *args], env=env,
                          capture_output=True, text=True, timeout=HANG_S)


@pytest.mark.parametrize("task_name, options, composed", [
    ("gymnasium:Acrobot-v1", [], False),
    ("gymnasium:Acrobot-v1", [], True),
    ("gymnasium:LunarLander-v3", ["--option", "reward_mapping=shaped"], False),
    ("gymnasium:InvertedPendulum-v5", ["--actions=-1,1"], False),
], ids=["acrobot", "acrobot-composed", "lunarlander-shaped", "invertedpendulum"])
def test_a_gymnasium_task_in_the_graph_equals_the_core(ros_env, tmp_path, task_name, options,
                                                       composed):
    trials, max_steps, seed = 4, 150, 3
    result = run_all(ros_env, "--env", task_name, *options, "--seed", str(seed), "--trials",
                     str(trials), "--max-steps", str(max_steps), "--no-record", "--out",
                     str(tmp_path), *(["--composed"] if composed else []))
    assert result.returncode == 0, result.stderr
    actions = next((o.split("=")[1] for o in options if o.startswith("--actions=")), None)
    changes = dict(o.split("=", 1) for o, before in zip(options[1:], options)
                   if before == "--option")
    task, env = make(task_name, actions)
    core = run_task_episode(seed, task_params(task, {"trials": str(trials),
                                                     "max_steps": str(max_steps), **changes}),
                            task, env)
    with open(tmp_path / "trials.csv") as f:
        rows = list(csv.DictReader(f))
    # the graph counts a trial's successful steps: those that did not terminate it
    assert [int(r["steps"]) for r in rows] == (core.steps - core.terminated).tolist()
    assert [r["end_reason"] == "terminated" for r in rows] == core.terminated.tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), core.final_weights)


def test_a_tasks_preset_in_the_graph_equals_the_task_batch_engine(ros_env, tmp_path):
    """`clnn-run --env gymnasium:Acrobot-v1 --preset acrobot_v1` runs what `learn --task
    gymnasium:Acrobot-v1 --preset acrobot_v1` runs (clnn_ros.task_batch)."""
    from clnn_ros.core.presets import preset_values
    from clnn_ros.task_batch import run_compiled_task_episode

    trials, seed = 4, 3
    result = run_all(ros_env, "--env", "gymnasium:Acrobot-v1", "--preset", "acrobot_v1",
                     "--seed", str(seed), "--trials", str(trials), "--no-record", "--out",
                     str(tmp_path))
    assert result.returncode == 0, result.stderr
    assert ", preset acrobot_v1" in result.stdout
    task, env = make("gymnasium:Acrobot-v1")
    p = task_params(task, {**preset_values("acrobot_v1"), "trials": str(trials)})
    batch = run_compiled_task_episode(seed, p, task, env)
    assert batch.terminated.any()  # it reached the line within these trials
    with open(tmp_path / "trials.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["steps"]) for r in rows] == (batch.steps - batch.terminated).tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), batch.final_weights)


def test_a_task_without_its_environment_is_refused_in_one_line(ros_env):
    result = run_all(ros_env, "--option", "task=gymnasium:Acrobot-v1", "--trials", "1")
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.count("\n") == 1 and "needs its own environment" in result.stderr


def with_nan_task(ros_env) -> dict:
    """The environment of a run whose processes can import tests/nan_task.py (Gymnasium imports
    the module an ID names)."""
    path = [str(Path(__file__).parent), *filter(None, [ros_env.get("PYTHONPATH")])]
    return {**ros_env, "PYTHONPATH": os.pathsep.join(path)}


def test_an_unknown_task_runs_and_its_broken_observation_is_named(ros_env, tmp_path):
    """A task that KNOWN does not name runs with the edges the user gives; at its third step its
    observation turns to NaN: the environment node refuses it in one line and exits 1, and the
    run's last line says so and names it."""
    result = run_all(with_nan_task(ros_env), "--env", UNKNOWN_TASK, "--option",
                     "variable_edges=x0:0;x1:0", "--trials", "2", "--no-record", "--out",
                     str(tmp_path))
    assert result.returncode == 1, result.stderr
    assert result.stderr.strip().splitlines()[-1] == (
        f"run_all: error: tick 3: {UNKNOWN_TASK}: an observation must be 2 finite numbers, "
        f"got [nan, nan] (node 'environment' exited with status 1)")


def test_an_unknown_task_without_its_edges_is_refused_in_one_line(ros_env):
    result = run_all(with_nan_task(ros_env), "--env", UNKNOWN_TASK, "--trials", "2")
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.count("\n") == 1
    assert "state_vars: unknown 'x0'" in result.stderr and "variable_edges" in result.stderr
