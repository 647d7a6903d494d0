"""The reproduction CLI (clnn_ros.reproduce): seed specs, `learn` outputs equal to the batch engine,
one-line errors without a traceback, and the calibration number (b) = 32 in paper mode."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clnn_ros.batch import run_batch
from clnn_ros.core.episode import returns
from clnn_ros.core.params import Params, params_from_strings
from clnn_ros.core.presets import preset_values
from clnn_ros.core.solving import solving_summary
from clnn_ros.core.physics import FAIL_POSITION
from clnn_ros.reproduce.__main__ import main
from clnn_ros.reproduce.calibration import constant_force_trial
from clnn_ros.reproduce.common import END_REASONS, parse_seeds

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("spec, seeds", [
    ("0-3", [0, 1, 2, 3]),
    ("0,3,5", [0, 3, 5]),
    ("0-3,7", [0, 1, 2, 3, 7]),
    (" 7 , 2-3 ", [2, 3, 7]),
    ("5-5", [5]),
    ("0-31", list(range(32))),
])
def test_parse_seeds_good(spec, seeds):
    assert parse_seeds(spec) == seeds


@pytest.mark.parametrize("spec", ["", " ", "a", "3-1", "-1", "1,,2", "1-2-3", "0-3,2", "1.5", "0-"])
def test_parse_seeds_bad(spec):
    with pytest.raises(ValueError) as info:
        parse_seeds(spec)
    assert "\n" not in str(info.value)


def _read_csv(path: Path) -> tuple[list[str], list[dict]]:
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return reader.fieldnames, list(reader)


@pytest.mark.parametrize("argv, params", [
    (["--nsv", "1"], Params(nsv=1, trials=8)),
    (["--nsv", "2", "--velocity-edge", "0.5", "--option", "e_flag=live"],
     Params(nsv=2, trials=8, velocity_edge=0.5, e_flag="live")),
    # CartPole-v1's protocol: truncated at 500 unless said otherwise
    (["--nsv", "1", "--protocol", "gymnasium", "--physics", "gymnasium"],
     Params(nsv=1, trials=8, protocol="gymnasium", physics="gymnasium", max_steps=500)),
])
def test_learn_writes_what_run_batch_computes(tmp_path, capsys, argv, params):
    seeds = [3, 5]
    rc = main(["learn", *argv, "--seeds", "3,5", "--trials", "8", "--out", str(tmp_path)])
    assert rc == 0
    ref = run_batch(seeds, params)
    tag = f"{params.nsv}sv"

    header, rows = _read_csv(tmp_path / f"learn_{tag}.csv")
    assert header == ["seed", "trial", "initial_angle_deg", "steps", "end_reason"]
    assert len(rows) == len(seeds) * 8
    for row in rows:
        k, trial = seeds.index(int(row["seed"])), int(row["trial"])
        assert float(row["initial_angle_deg"]) == ref.initial_angles[k, trial]
        assert int(row["steps"]) == ref.steps[k, trial]
        assert row["end_reason"] == END_REASONS[int(ref.end_status[k, trial])]

    saved = np.load(tmp_path / f"final_weights_{tag}.npz")
    np.testing.assert_array_equal(saved["final_weights"], ref.final_weights)
    np.testing.assert_array_equal(saved["seeds"], seeds)
    header, rows = _read_csv(tmp_path / f"final_weights_{tag}.csv")
    assert header == ["seed", "neuron", "segment", "input", "weight"]
    assert len(rows) == ref.final_weights.size
    for row in rows[:50]:
        k = seeds.index(int(row["seed"]))
        assert float(row["weight"]) == ref.final_weights[k, int(row["neuron"]), int(row["segment"]),
                                                          int(row["input"])]
    out = capsys.readouterr().out
    assert f"overall mean {ref.steps.mean():.1f}" in out


@pytest.mark.parametrize("bad", [
    ["--option", "tie_break=bogus"],
    ["--option", "no_such_field=1"],
    ["--option", "novalue"],
    ["--seeds", "3-1"],
    ["--velocity-edge", "fast"],
    ["--protocol", "atari"],
    ["--protocol", "gymnasium", "--option", "max_steps=1000"],
])
def test_bad_input_is_one_line_exit_2(tmp_path, bad):
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.run([sys.executable, "-m", "clnn_ros.reproduce", "learn", "--nsv", "1",
                           "--trials", "2", "--out", str(tmp_path), *bad],
                          capture_output=True, text=True, cwd=ROOT, env=env, timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr and "error" in lines[0]
    assert not (tmp_path / "learn_1sv.csv").exists()


def test_calibrate_b_is_32_in_paper_mode(tmp_path, capsys):
    p = Params()
    assert constant_force_trial(p, +p.force) == (32, FAIL_POSITION)
    assert constant_force_trial(p, -p.force) == (32, FAIL_POSITION)
    assert main(["calibrate", "--out", str(tmp_path)]) == 0
    _, rows = _read_csv(tmp_path / "calib_constant_force.csv")
    paper = [r for r in rows if (r["physics"], r["integrator"]) == ("paper", "semi_implicit")]
    assert {(r["force"], r["steps"], r["end_reason"]) for r in paper} == {
        ("+F", "32", "cart_position"), ("-F", "32", "cart_position")}
    assert "paper/semi_implicit" in capsys.readouterr().out


def test_integration_slip_reading_gives_29_steps():
    """The other reading of the units slip (the cart sees the true theta_acc) misses (b) = 32."""
    p = Params(physics="integration_slip")
    assert constant_force_trial(p, +p.force) == (29, FAIL_POSITION)


def test_sweep_writes_a_csv_per_configuration_and_a_summary(tmp_path, capsys):
    assert main(["sweep", "--param", "sigma=128,256", "--param", "omega=64,256", "--nsv", "1",
                 "--seeds", "0-2", "--trials", "6", "--out", str(tmp_path)]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["runs", "sweep.png", "sweep_sigma=128_omega=256.csv", "sweep_sigma=128_omega=64.csv",
                     "sweep_sigma=256_omega=256.csv", "sweep_sigma=256_omega=64.csv",
                     "sweep_summary.csv", "sweep_summary.md"]
    _, rows = _read_csv(tmp_path / "sweep_summary.csv")
    for row in rows:  # each configuration is the batch engine's run of those values
        p = Params(trials=6, sigma=int(row["sigma"]), omega=int(row["omega"]))
        assert float(row["mean_steps"]) == round(float(run_batch([0, 1, 2], p).steps.mean()), 2)
    _, trials = _read_csv(tmp_path / "sweep_sigma=128_omega=64.csv")
    assert len(trials) == 3 * 6
    assert "| sigma | omega | mean steps |" in (tmp_path / "sweep_summary.md").read_text()


def test_a_sweep_under_cartpole_v1s_protocol_says_which_seeds_solved_it(tmp_path, capsys):
    """Episodes end at 500 steps there: seeds below 1,000 would say nothing; the summary counts
    the seeds that solved CartPole-v1 and the median episodes it took them (core.solving)."""
    assert main(["sweep", "--protocol", "gymnasium", "--preset", "cartpole_v1", "--param",
                 "sigma=64,128", "--seeds", "0-3", "--trials", "200", "--out", str(tmp_path)]) == 0
    header, rows = _read_csv(tmp_path / "sweep_summary.csv")
    assert header[-3:] == ["mean_steps", "seeds_solved", "median_episodes_to_solve"]
    for row in rows:
        p = params_from_strings({**preset_values("cartpole_v1"), "protocol": "gymnasium",
                                 "trials": "200", "sigma": row["sigma"]})
        batch = run_batch(range(4), p)
        solving = solving_summary([returns(steps, status) for steps, status
                                   in zip(batch.steps, batch.end_status)])
        assert int(row["seeds_solved"]) == solving["solved"]
        assert row["median_episodes_to_solve"] == (str(solving["episodes"][1])
                                                   if solving["solved"] else "")
    assert sum(int(row["seeds_solved"]) for row in rows) > 0  # solving is exercised
    assert "| sigma | mean steps | seeds solved | median episodes to solve |" in \
        (tmp_path / "sweep_summary.md").read_text()


def test_an_interrupted_sweep_resumes_without_running_a_finished_configuration(
        tmp_path, capsys, monkeypatch):
    from clnn_ros.reproduce import common
    argv = ["sweep", "--param", "sigma=128,256", "--nsv", "1", "--seeds", "0-1", "--trials", "4",
            "--out", str(tmp_path)]
    assert main([argv[0], "--param", "sigma=128", *argv[3:]]) == 0  # as if stopped after it
    first = (tmp_path / "sweep_sigma=128.csv").read_text()
    calls = []
    real_run_batch = common.run_batch
    monkeypatch.setattr(common, "run_batch", lambda seeds, p: calls.append(p.sigma)
                        or real_run_batch(seeds, p))
    assert main(argv) == 0
    assert calls == [256]
    assert (tmp_path / "sweep_sigma=128.csv").read_text() == first


@pytest.mark.parametrize("bad, message", [
    (["--param", "sigma"], "--param expects NAME=V1,V2"),
    (["--param", "sigma=1,x"], "sigma must be an integer"),
    (["--param", "trials=3"], "--param trials: not a model parameter"),
    ([], "give at least one --param"),
])
def test_sweep_refuses_bad_grids_before_running(tmp_path, capsys, bad, message):
    assert main(["sweep", *bad, "--seeds", "0", "--trials", "2", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "o").exists()
