"""Presets (named parameter sets) on every way in: `clnn-reproduce presets`, `learn/sweep
--preset` and `clnn-run --preset`, where the command's own flags and options win; and
`clnn-reproduce gym-eval`, the learned weights frozen in gymnasium's CartPole-v1 itself."""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest

from clnn_ros import run_all
from clnn_ros.batch import run_batch
from clnn_ros.core.encoder import Encoder
from clnn_ros.core.physics import GYM_PHYSICS, gym_matched_params
from clnn_ros.core.params import CARTPOLE, Params, params_from_strings
from clnn_ros.core.physics import CartPole, at_rest
from clnn_ros.core.presets import PRESETS, Preset, overlay_values, preset_task, preset_values
from clnn_ros.core.agent import RLNAgent
from clnn_ros.reproduce.__main__ import build_parser, learn_params, main
from clnn_ros.reproduce.common import TRIALS
from clnn_ros.reproduce.gym_eval import GYM_ID, frozen, gym_eval, load_learn_output, reset_seed

from conftest import free_domain_id, ros_environment

DOMAIN_ID = free_domain_id()
# A preset of the test's own, to check the layering whatever the project's presets hold.
LAYERED = Preset("for the test", {"trials": "7", "state_vars": "pole_angle,cart_velocity",
                                  "sigma": "64"})


@pytest.fixture
def layered_preset(monkeypatch):
    monkeypatch.setitem(PRESETS, "layered", LAYERED)
    return "layered"


def one_error_line(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


# The cart-pole's presets (a task's: tests/test_task_batch.py)
CARTPOLE_PRESETS = [name for name in PRESETS if preset_task(name) == CARTPOLE]


@pytest.mark.parametrize("name", PRESETS)
def test_a_preset_is_valid_params(name):
    assert set(preset_values(name)) <= set(Params().to_dict())
    params_from_strings(preset_values(name))  # raises ParamError when one is not


def test_the_gymnasium_preset_has_gymnasiums_physics():
    p = params_from_strings(preset_values("gymnasium"))
    matched = gym_matched_params(Params())
    assert {name: getattr(p, name) for name in GYM_PHYSICS} == \
        {name: getattr(matched, name) for name in GYM_PHYSICS}


def test_presets_lists_every_preset(capsys):
    assert main(["presets"]) == 0
    out = capsys.readouterr().out
    for name, preset in PRESETS.items():
        assert f"{name}: {preset.description}" in out
        for key, value in preset.values.items():
            assert f"    {key}={value}\n" in out


def test_an_unknown_preset_is_one_line_exit_2(tmp_path, capsys):
    proc = subprocess.run([sys.executable, "-m", "clnn_ros.reproduce", "learn", "--preset",
                           "no_such_preset", "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert lines[0].endswith(f"unknown preset 'no_such_preset'; known: {', '.join(PRESETS)}")
    assert not (tmp_path / "o").exists()
    assert run_all.main(["--preset", "no_such_preset", "--no-record"]) == 2
    assert one_error_line(capsys) == \
        f"run_all: error: unknown preset 'no_such_preset'; known: {', '.join(PRESETS)}"


def test_overlay_values_lets_nsv_and_state_vars_replace_each_other():
    assert overlay_values({"nsv": 1, "sigma": 8}, {"state_vars": "a,b"}) == \
        {"sigma": 8, "state_vars": "a,b"}
    assert overlay_values({"state_vars": "a,b"}, {"nsv": 1}) == {"nsv": 1}
    both = {"nsv": 2, "state_vars": "a"}  # given together: kept, for Params to check
    assert overlay_values({"nsv": 1}, both) == both


def parse_learn(*argv: str) -> Params:
    return learn_params(build_parser().parse_args(["learn", *argv]))


def test_learn_takes_the_preset_and_its_flags_and_options_win(layered_preset):
    p = parse_learn("--preset", layered_preset)
    assert (p.trials, p.state_vars, p.sigma) == (7, ("pole_angle", "cart_velocity"), 64)
    p = parse_learn("--preset", layered_preset, "--trials", "9", "--nsv", "1",
                    "--option", "sigma=32")
    assert (p.trials, p.state_vars, p.sigma) == (9, ("pole_angle",), 32)


def test_learn_keeps_its_default_trials_under_a_preset_without_them(monkeypatch):
    monkeypatch.setitem(PRESETS, "no_trials", Preset("for the test", {"sigma": "64"}))
    assert parse_learn("--preset", "no_trials").trials == parse_learn().trials == TRIALS


def test_run_all_takes_the_preset_and_its_flags_and_options_win(layered_preset, tmp_path):
    values = run_all.build_parameters(run_all.parse_args(["--preset", layered_preset]))
    assert (values["trials"], values["state_vars"], values["sigma"]) == \
        (7, ["pole_angle", "cart_velocity"], 64)
    params_file = tmp_path / "params.yaml"
    params_file.write_text("/**:\n  ros__parameters:\n    sigma: 48\n    omega: 48\n")
    values = run_all.build_parameters(run_all.parse_args([
        "--preset", layered_preset, "--params-file", str(params_file), "--trials", "9",
        "--nsv", "1", "--option", "omega=32"]))
    assert (values["trials"], values["nsv"], values["sigma"], values["omega"]) == (9, 1, 48, 32)
    assert "state_vars" not in values


@pytest.mark.parametrize("name", CARTPOLE_PRESETS)
def test_learn_with_a_preset_and_an_option(tmp_path, name):
    """The saved run's parameters: the preset's values, the option over them."""
    assert main(["learn", "--preset", name, "--option", "explore=0.5", "--seeds", "3",
                 "--trials", "4", "--out", str(tmp_path)]) == 0
    assert load_learn_output(tmp_path, None).params == \
        params_from_strings({**preset_values(name), "trials": "4", "explore": "0.5"})


@pytest.fixture(scope="module")
def learned(tmp_path_factory) -> dict[str, Path]:
    """Tiny learn outputs (2 seeds, few trials) for each tie-break kind: looked-up actions
    (exact) and inferred on every step (random)."""
    outputs = {}
    for tie_break in ("exact", "random"):
        out = tmp_path_factory.mktemp(f"learn_{tie_break}")
        assert main(["learn", "--nsv", "2", "--velocity-edge", "0.3", "--physics", "correct",
                     "--option", f"tie_break={tie_break}", "--seeds", "3,5", "--trials", "6",
                     "--out", str(out)]) == 0
        outputs[tie_break] = out
    return outputs


@pytest.mark.parametrize("tie_break", ["exact", "random"])
def test_gym_eval_writes_a_return_per_seed_and_episode(learned, tie_break, capsys):
    out = learned[tie_break]
    assert main(["gym-eval", str(out), "--episodes", "3"]) == 0
    first = (out / "gym_eval.csv").read_bytes()
    rows = read_rows(out / "gym_eval.csv")
    assert list(rows[0]) == ["seed", "episode", "return"]
    assert [(int(r["seed"]), int(r["episode"])) for r in rows] == \
        [(seed, episode) for seed in (3, 5) for episode in range(3)]
    assert all(1 <= int(r["return"]) <= 500 for r in rows)
    assert "seeds averaging >= 475" in capsys.readouterr().out
    assert main(["gym-eval", str(out), "--episodes", "3"]) == 0
    assert (out / "gym_eval.csv").read_bytes() == first


def test_gym_eval_plays_as_the_core_infers_step_by_step(learned):
    """The looked-up actions are those of the core's inference on every step of gymnasium's
    episode (observation radians -> degrees), from the documented reset seed."""
    learn = load_learn_output(learned["exact"], None)
    returns = gym_eval(learn, episodes=3, seed_offset=0)
    p = frozen(learn.params)
    encoder = Encoder.from_params(p)
    with gymnasium.make(GYM_ID) as env:
        for k, seed in enumerate(learn.seeds.tolist()):
            agent = RLNAgent(p, learn.final_weights[k], seed=seed)
            for episode in range(3):
                observation, _ = env.reset(seed=reset_seed(seed, episode, 0))
                total, done = 0, False
                while not done:
                    x, x_dot, theta, theta_dot = (float(v) for v in observation)
                    spikes = encoder.spikes((x, x_dot, math.degrees(theta),
                                             math.degrees(theta_dot)))
                    observation, reward, terminated, truncated, _ = \
                        env.step(agent.infer(spikes)[0])
                    total, done = total + reward, terminated or truncated
                assert returns[k, episode] == total


def test_gym_eval_seed_offset_shifts_the_episodes(learned):
    learn = load_learn_output(learned["exact"], None)
    np.testing.assert_array_equal(gym_eval(learn, 2, 1)[:, 0], gym_eval(learn, 2, 0)[:, 1])


def test_action_1_pushes_forward_in_gymnasium_and_in_the_core():
    with gymnasium.make(GYM_ID) as env:
        for action, sign in ((0, -1), (1, +1)):
            before, _ = env.reset(seed=0)
            after, *_ = env.step(action)
            assert np.sign(after[1] - before[1]) == sign
    for action, sign in ((0, -1), (1, +1)):
        cartpole = CartPole(Params())
        cartpole.reset(at_rest(0.0))
        cartpole.step(action)
        assert np.sign(cartpole.state[1]) == sign


def test_frozen_turns_exploration_off():
    assert frozen(Params(explore=0.3)).explore == 0


@pytest.mark.parametrize("setup, args, message", [
    (None, [], "no such folder"),
    ("empty", [], "holds no final_weights_*.npz"),
    ("two", [], "holds several runs (1sv, 2sv): choose one with --run"),
    ("two", ["--run", "3sv"], "holds no run '3sv'; it holds 1sv, 2sv"),
    ("junk", [], "is not an output of clnn-reproduce learn"),
    ("two", ["--run", "1sv", "--episodes", "0"], "--episodes must be at least 1, got 0"),
])
def test_gym_eval_bad_input_is_one_line_exit_2(learned, tmp_path, capsys, setup, args, message):
    folder = tmp_path / "out"
    if setup is not None:
        folder.mkdir()
    if setup == "two":
        npz = next(learned["exact"].glob("final_weights_*.npz")).read_bytes()
        for name in ("1sv", "2sv"):
            (folder / f"final_weights_{name}.npz").write_bytes(npz)
    if setup == "junk":
        (folder / "final_weights_1sv.npz").write_text("not a zip\n")
    assert main(["gym-eval", str(folder), *args]) == 2
    assert message in one_error_line(capsys)
    assert not (folder / "gym_eval.csv").exists()


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)


@pytest.mark.ros
@pytest.mark.parametrize("name", CARTPOLE_PRESETS)
def test_run_all_with_a_preset_equals_the_batch_engine(ros_env, tmp_path, name):
    """The graph runs the preset on the project's own cart-pole node, as the batch engine does
    with the same values."""
    seed, trials = 3, 6
    max_steps = int(preset_values(name).get("max_steps", 300))  # the protocol's, where it has one
    result = subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--preset",
                             name, "--seed", str(seed), "--trials", str(trials), "--max-steps",
                             str(max_steps), "--no-record", "--out", str(tmp_path)],
                            env=ros_env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    assert f", preset {name}" in result.stdout and "environment:" not in result.stdout
    p = params_from_strings({**preset_values(name), "trials": str(trials),
                             "max_steps": str(max_steps)})
    ref = run_batch([seed], p)
    steps = [int(row["steps"]) for row in read_rows(tmp_path / "trials.csv")]
    assert steps == ref.steps[0].tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), ref.final_weights[0])
