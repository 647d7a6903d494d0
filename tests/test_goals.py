"""clnn-reproduce goals: its measures, its report and its resume."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from clnn_ros.core.params import Params
from clnn_ros.core.physics import CONTINUE, FAIL_ANGLE
from clnn_ros.reproduce import common, goals
from clnn_ros.reproduce.__main__ import main


def outcome(steps, status) -> goals.Outcome:
    steps = np.asarray(steps)
    return goals.Outcome("gymnasium", "t", Params(), np.arange(len(steps)), steps,
                         np.asarray(status), np.zeros((len(steps), 2, 3, 6)))


def test_a_trial_counts_as_cartpole_v1_counts_it():
    o = outcome([[474, 474, 10_000]], [[FAIL_ANGLE, FAIL_ANGLE, CONTINUE]])
    np.testing.assert_array_equal(o.gym_returns(), [[475, 475, 500]])


def test_solved_at_is_the_first_trial_whose_100_trial_mean_reaches_475():
    failing = np.full((3, 150), FAIL_ANGLE)
    steps = np.full((3, 150), 474)  # returns of 475: solved at the 100th trial
    steps[1, :] = 473  # 474: never
    steps[2, :60] = 0  # 1 for 60 trials, then 475: the window is full of 475 at trial 160: never
    np.testing.assert_array_equal(outcome(steps, failing).solved_at(), [100, 0, 0])
    assert outcome(steps[:, :50], failing[:, :50]).solved_at().tolist() == [0, 0, 0]


def test_rolling_converged_counts_seeds_per_trial():
    steps = np.full((2, goals.LAST_TRIALS + 1), 10_000)
    steps[1, -1] = 0
    curve = outcome(steps, np.zeros_like(steps)).rolling_converged(9900)  # 63 x 10,000 + 0: 9,844
    np.testing.assert_array_equal(curve, [1.0, 0.5])


def test_goals_writes_its_report_and_resumes_without_running_again(tmp_path, monkeypatch, capsys):
    argv = ["goals", "--out", str(tmp_path), "--report-seeds", "0-1", "--select-seeds", "2-3",
            "--trials", "6", "--episodes", "2"]
    assert main(argv) == 0
    report = (tmp_path / "LEARNING.md").read_text()
    assert "## Goals against measurement" in report and "| **no** |" in report
    assert (tmp_path / "figures" / "learning_curves.png").stat().st_size > 0
    with open(tmp_path / "data" / "learning_gym_eval.csv") as f:
        rows = list(csv.DictReader(f))
    assert [(r["seed"], r["episode"]) for r in rows] == [("0", "0"), ("0", "1"), ("1", "0"),
                                                          ("1", "1")]
    assert all(1 <= int(r["return"]) <= 500 for r in rows)
    with open(tmp_path / "data" / "learning_rerandomization_grid.csv") as f:
        assert len(list(csv.DictReader(f))) == len(goals.WORLDS) * len(list(goals.grid_points()))

    def no_more_runs(*_args, **_kwargs):
        raise AssertionError("a finished run was run again")

    monkeypatch.setattr(common, "run_batch", no_more_runs)
    monkeypatch.setattr(goals, "run_batch", no_more_runs)
    assert main(argv) == 0
    assert (tmp_path / "LEARNING.md").read_text() == report


@pytest.mark.parametrize("world", goals.WORLDS)
def test_each_world_and_its_preset_are_valid(world):
    assert goals.preset_params(world, 8).trials == 8
    assert goals.world_params(world, 8) != goals.preset_params(world, 8)
