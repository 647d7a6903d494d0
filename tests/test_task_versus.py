"""`clnn-reproduce versus --task gymnasium:ID` (clnn_ros.reproduce.task_versus): the RLN agent's
seeds are the core's episodes with the task's preset, stored and not run again; the report is
rebuilt from the store; what cannot run is refused in one line. (PPO and DQN need the baselines
extra: tests/test_baselines_sb3.py.)"""

from __future__ import annotations

import csv

import numpy as np
import pytest

from clnn_ros.core.presets import preset_values
from clnn_ros.core.solving import solved_episode
from clnn_ros.core.task_episode import run_task_episode
from clnn_ros.reproduce.__main__ import main
from clnn_ros.reproduce.common import store_arrays
from clnn_ros.reproduce.task_versus import PLAY_EPISODES, TASKS, agent_key
from clnn_ros.reproduce.versus import stored_seed
from clnn_ros.tasks.gymnasium_task import make, task_params


def test_versus_a_task_runs_the_rln_agent_and_reports_it(tmp_path, capsys):
    argv = ["versus", "--task", "gymnasium:Acrobot-v1", "--agents", "rln", "--seeds", "0-1",
            "--workers", "1", "--out", str(tmp_path)]
    assert main(argv) == 0
    report = (tmp_path / "VERSUS_TASKS.md").read_text()
    with open(tmp_path / "data" / "versus_Acrobot-v1_seeds.csv") as f:
        rows = list(csv.DictReader(f))
    assert [(r["agent"], r["seed"]) for r in rows] == [("rln", "0"), ("rln", "1")]
    task, env = make("gymnasium:Acrobot-v1")
    p = task_params(task, {**preset_values("acrobot_v1"),
                           "trials": str(TASKS["Acrobot-v1"].episodes)})
    core = run_task_episode(0, p, task, env)  # the pure core, Gymnasium's own step
    at = solved_episode(core.returns, task.reward_threshold)
    assert rows[0]["solved_episode"] == ("" if at is None else str(at))
    assert int(rows[0]["env_steps"]) == core.steps.sum()
    assert int(rows[0]["episodes"]) == p.trials
    assert "| Acrobot-v1 | RLN agent, preset acrobot_v1 |" in report
    assert (tmp_path / "figures" / "versus_Acrobot-v1.png").stat().st_size > 0
    stored = sorted((tmp_path / "data" / "versus_tasks" / "Acrobot-v1" / "rln").iterdir())
    assert len(stored) == 2
    with np.load(stored[0]) as arrays:
        assert len(arrays["play"]) == PLAY_EPISODES
    mtimes = [path.stat().st_mtime_ns for path in stored]
    capsys.readouterr()
    assert main([*argv[:-2], "--stored-only", "--out", str(tmp_path)]) == 0  # runs nothing
    assert [path.stat().st_mtime_ns for path in stored] == mtimes
    assert (tmp_path / "VERSUS_TASKS.md").read_text() == report


def test_a_run_of_one_agent_keeps_the_others_stored_in_the_report(tmp_path, capsys):
    """A later `--agents rln` must not drop PPO's stored seeds from the report (it did: the
    report held the agents of the last command alone)."""
    store = tmp_path / "data" / "versus_tasks" / "Acrobot-v1" / "ppo"
    ppo = dict(returns=np.full(150, -90.0), env_steps=np.arange(1, 151) * 90,
               cpu_s=np.float64(12.5), play=np.full(PLAY_EPISODES, -95.0))
    store_arrays(stored_seed(store, 0, agent_key("Acrobot-v1", "ppo")), ppo)
    argv = ["versus", "--task", "gymnasium:Acrobot-v1", "--agents", "rln", "--seeds", "0-0",
            "--deep-seeds", "1", "--workers", "1", "--out", str(tmp_path)]
    assert main(argv) == 0
    report = (tmp_path / "VERSUS_TASKS.md").read_text()
    assert "| Acrobot-v1 | RLN agent, preset acrobot_v1 | 1 of 1 |" in report
    assert "| Acrobot-v1 | PPO, rl-zoo3's hyperparameters (stable-baselines3) | 1 of 1 | 9,000 " \
           "| 12.5 | 100% |" in report
    with open(tmp_path / "data" / "versus_Acrobot-v1_seeds.csv") as f:
        assert [(r["agent"], r["seed"]) for r in csv.DictReader(f)] == [("rln", "0"),
                                                                        ("ppo", "0")]


@pytest.mark.parametrize("argv, message", [
    (["--task", "gymnasium:CartPole-v1"], "versus --task takes gymnasium:Acrobot-v1, "),
    (["--task", "gymnasium:Acrobot-v1", "--agents", "ase_ace"], "unknown agent 'ase_ace' for "
                                                                "--task; known: rln, ppo, dqn"),
    (["--task", "gymnasium:Acrobot-v1", "--agents", "rln", "--stored-only"],
     "--stored-only: no agent-seed of Acrobot-v1 stored in"),
])
def test_versus_a_task_refuses_in_one_line(argv, message, tmp_path, capsys):
    assert main(["versus", *argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
