"""CartPole-v1's own protocol (issue 34): the core's "gymnasium" physics is Gymnasium's step bit
for bit, the protocol's starts are Gymnasium's reset() draws, and an episode on Gymnasium itself
equals the batch engine's on the core's physics, trial by trial and in the final weights."""

import contextlib
import csv
import math
import os
import signal
import subprocess
import sys
import time

import gymnasium
import numpy as np
import pytest

from clnn_ros.batch import run_batch
from clnn_ros.core.episode import STARTS_SEED, returns, run_episode, trial_starts
from clnn_ros.core.physics import gym_exact_params
from clnn_ros.tasks.cartpole.gymnasium_cartpole import GymCartPole
from clnn_ros.core.params import GYMNASIUM_MAX_STEPS, ParamError, Params, params_from_strings
from clnn_ros.core.physics import (CONTINUE, FAIL_ANGLE, FAIL_POSITION, CartPole, at_rest,
                                   physics_constants)
from clnn_ros.core.presets import preset_values
from clnn_ros.core.solving import solved_episode, solving_summary, steps_to_solve
from clnn_ros.reproduce.__main__ import main as reproduce_main
from clnn_ros.reproduce.common import load_stored, store_arrays
from clnn_ros.reproduce.versus import has_baselines_extra

from conftest import free_domain_id, ros_environment

DOMAIN_ID = free_domain_id()
HANG_S = 240  # a bound against a hang, never a speed bound


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)


def gymnasium_params(**changes) -> Params:
    return gym_exact_params(Params(protocol="gymnasium", max_steps=GYMNASIUM_MAX_STEPS,
                                   **changes))


@pytest.mark.parametrize("integrator", ["euler", "semi_implicit"])
def test_the_gymnasium_physics_is_gymnasiums_step_bit_for_bit(integrator):
    """Trajectories of random actions from Gymnasium's own starts, to the failure: the same
    state after every step (in radians inside, in degrees as the encoder sees it) and the same
    failures, on both of Gymnasium's integrators."""
    p = gymnasium_params().replace(integrator=integrator)
    env = gymnasium.make("CartPole-v1", max_episode_steps=None).unwrapped
    if integrator == "semi_implicit":
        env.kinematics_integrator = "semi-implicit euler"
    ours = CartPole(p)
    actions = np.random.default_rng(7)
    steps = ends = 0
    for episode in range(40):
        env.reset(seed=episode)
        ours.reset(env.state.copy(), start_in_radians=True)
        while True:
            action = int(actions.integers(2))
            status = ours.step(action)
            _, _, terminated, _, _ = env.step(action)
            steps += 1
            x, x_dot, theta, theta_dot = (float(v) for v in env.state)
            # as the graph's gymnasium node publishes it (GymCartPole)
            assert ours.state == (x, x_dot, math.degrees(theta), math.degrees(theta_dot))
            assert ours.state_in_own_units == (x, x_dot, theta, theta_dot)
            assert (status != CONTINUE) == terminated
            if terminated:
                ends += 1
                assert status == (FAIL_ANGLE if abs(theta) > env.theta_threshold_radians
                                  else FAIL_POSITION)
                break
    assert ends == 40 and steps > 400


def test_gymnasium_protocol_starts_are_cartpole_v1_resets():
    """Trial k of seed s starts where CartPole-v1's (k+1)-th reset puts it after
    reset(seed=STARTS_SEED + s): the four variables in +-0.05, radians."""
    p = gymnasium_params(trials=20)
    env = gymnasium.make("CartPole-v1").unwrapped
    for seed in (0, 3):
        env.reset(seed=STARTS_SEED + seed)
        resets = [env.state.copy()]
        for _ in range(p.trials - 1):
            env.reset()
            resets.append(env.state.copy())
        starts, in_radians = trial_starts(seed, p)
        assert in_radians
        np.testing.assert_array_equal(starts, np.array(resets))
    assert np.all(np.abs(trial_starts(5, gymnasium_params(trials=512))[0]) <= 0.05)


def test_an_episode_on_gymnasium_itself_equals_the_batch_engine():
    """The core driving Gymnasium's own CartPole-v1 (GymCartPole) under its protocol equals the
    batch engine on the core's gymnasium physics, trial by trial and in the final weights; the
    protocol truncates at 500 successful steps, with no punishment."""
    p = gymnasium_params(trials=40, nsv=2, velocity_edge=0.5, sigma=16)
    seeds = [2, 7]  # each reaches the truncation once or more
    batch = run_batch(seeds, p)
    for k, seed in enumerate(seeds):
        core = run_episode(seed, p, env_factory=GymCartPole)
        np.testing.assert_array_equal(batch.steps[k], core.steps, err_msg=f"seed {seed}")
        np.testing.assert_array_equal(batch.end_status[k], core.end_status)
        np.testing.assert_array_equal(batch.initial_angles[k], core.initial_angles)
        np.testing.assert_array_equal(batch.final_weights[k], core.final_weights)
    assert batch.steps.max() == GYMNASIUM_MAX_STEPS
    assert set(batch.end_status[batch.steps == GYMNASIUM_MAX_STEPS]) == {CONTINUE}
    assert len(set(batch.initial_angles[0])) == p.trials  # each trial its own random start


def test_the_paper_protocol_on_the_gymnasium_physics_starts_at_rest_in_radians():
    """The paper's starts (degrees) on a physics that keeps radians: math.radians of the angle."""
    p = gym_exact_params(Params(trials=8))
    ours, theirs = CartPole(p), GymCartPole()
    for angle in (-1.5, 0.3, 1.5):
        assert ours.reset(at_rest(angle)) == theirs.reset(at_rest(angle))
    assert physics_constants(p)[-1] == theirs.env.theta_threshold_radians


def test_returns_count_the_failing_step():
    """Gymnasium's return: the steps taken, the failing one included; a truncated trial 500."""
    np.testing.assert_array_equal(
        returns(np.array([10, 500, 0]), np.array([FAIL_ANGLE, CONTINUE, FAIL_POSITION])),
        [11, 500, 1])


def test_the_gymnasium_protocol_truncates_at_500():
    with pytest.raises(ParamError, match="protocol gymnasium truncates a trial at 500 steps"):
        Params(protocol="gymnasium")
    with pytest.raises(ParamError, match="protocol must be one of 'paper', 'gymnasium'"):
        Params(protocol="atari")


@pytest.mark.parametrize("returns, expected", [
    ([475] * 100, 100),
    ([500] * 99, None),
    ([475] * 99 + [474], None),
    ([0] * 50 + [500] * 150, 145),
    ([500] * 90 + [0] * 10 + [500] * 100, 195),  # the dip holds every window under 475 till 195
    ([500] * 100 + [0] * 100, 100),
])
def test_solved_is_the_first_full_window_at_475(returns, expected):
    assert solved_episode(returns) == expected


def test_solving_is_judged_on_the_last_100_training_returns():
    """Solved at the first episode whose last 100 returns average 475 or more; the steps to
    solve count every episode up to it."""
    returns_row = [20] * 50 + [475] * 99 + [474, 476] + [500] * 10
    assert solved_episode(returns_row[:149]) is None  # 99 of 475: still 50 of 20 in the window
    # episodes 52-151 (1-based): 474 and 476 make up for each other, 98 x 475
    assert solved_episode(returns_row) == 151
    assert steps_to_solve(returns_row) == 50 * 20 + 99 * 475 + 474 + 476
    assert solved_episode([500] * 99) is None  # fewer than 100 episodes
    summary = solving_summary([returns_row, [10] * 200, [500] * 100])
    assert summary["seeds"] == 3 and summary["solved"] == 2
    assert summary["episodes"][1] == (100 + 151) / 2


@pytest.mark.ros
# The acceptance run; and seed 28, whose 7th trial is truncated at 500 steps.
@pytest.mark.parametrize("env, seed, trials", [("gymnasium", 3, 64), ("cartpole", 28, 12)])
def test_the_graph_under_cartpole_v1s_protocol_equals_the_batch_engine(ros_env, tmp_path, env,
                                                                        seed, trials):
    """`clnn-run --env gymnasium --protocol gymnasium --preset cartpole_v1`: the environment node
    draws each start with Gymnasium's own reset() (or, as the project's cart-pole, from the
    START's seed), and trials.csv and the final weights equal the batch engine's."""
    result = subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--env", env,
                             "--protocol", "gymnasium", "--preset", "cartpole_v1", "--seed",
                             str(seed), "--trials", str(trials), "--no-record", "--out",
                             str(tmp_path)], env=ros_env, capture_output=True, text=True,
                            timeout=600)
    assert result.returncode == 0, result.stderr
    ref = run_batch([seed], params_from_strings({**preset_values("cartpole_v1"),
                                                 "trials": str(trials)}))
    with open(tmp_path / "trials.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(row["steps"]) for row in rows] == ref.steps[0].tolist()
    assert [float(row["initial_angle_deg"]) for row in rows] == ref.initial_angles[0].tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), ref.final_weights[0])
    if env == "cartpole":
        assert GYMNASIUM_MAX_STEPS in ref.steps[0]  # the truncation is exercised


def test_versus_runs_the_agents_alike_and_resumes(tmp_path, capsys):
    """clnn-reproduce versus: a row per agent from its stored agent-seeds; run again, nothing is
    run anew (the stored files stay as they were)."""
    argv = ["versus", "--seeds", "0-1", "--agents", "rln,ase_ace", "--out", str(tmp_path),
            "--workers", "1"]
    assert reproduce_main(argv) == 0
    report = (tmp_path / "VERSUS.md").read_text()
    assert "| RLN agent, preset cartpole_v1 (the batch engine) | 2 of 2 |" in report
    assert "| ASE/ACE on the 162 boxes (Barto, Sutton & Anderson 1983) |" in report
    assert (tmp_path / "figures" / "versus_returns.png").stat().st_size > 0
    rows = list(csv.DictReader(open(tmp_path / "data" / "versus_seeds.csv")))
    assert [(r["agent"], r["seed"]) for r in rows] == \
        [("rln", "0"), ("rln", "1"), ("ase_ace", "0"), ("ase_ace", "1")]
    stored = {p: p.stat().st_mtime_ns for p in (tmp_path / "data" / "versus").rglob("*.npz")}
    assert len(stored) == 4
    assert reproduce_main(argv) == 0
    assert {p: p.stat().st_mtime_ns for p in stored} == stored
    table = [line for line in report.splitlines() if line.startswith("| ")]
    assert [line for line in (tmp_path / "VERSUS.md").read_text().splitlines()
            if line.startswith("| ")] == table
    # --stored-only runs nothing: an agent short of its seeds is named
    assert reproduce_main([*argv, "--seeds", "0-2", "--stored-only"]) == 0
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "data" / "versus").rglob("*.npz")} \
        == stored
    report = (tmp_path / "VERSUS.md").read_text()
    assert "| RLN agent, preset cartpole_v1 (the batch engine) | 2 of 2 |" in report
    assert "Partial (`--stored-only`, the rest not run yet): RLN agent, preset cartpole_v1 " \
        "(the batch engine): 2 of its 3 seeds; ASE/ACE on the 162 boxes (Barto, Sutton & " \
        "Anderson 1983): 2 of its 3 seeds." in report
    assert reproduce_main([*argv, "--seeds", "5", "--stored-only"]) == 2
    assert "no agent-seed of these stored" in capsys.readouterr().err


@pytest.mark.skipif(has_baselines_extra(), reason="the case of a user without the extra")
def test_versus_stored_only_reports_deep_agents_without_the_baselines_extra(tmp_path, capsys):
    """The report of stored agent-seeds runs no deep agent: a user without torch regenerates it
    from PPO's stored seeds (issue 47: refused, asking for the extra); running PPO still needs
    the extra, said in one line."""
    returns = np.full(120, 500.0)  # as a PPO run elsewhere stored it: solved at episode 100
    store_arrays(tmp_path / "data" / "versus" / "ppo" / "seed_0_0123456789abcdef.npz",
                 dict(returns=returns, env_steps=np.cumsum(returns), cpu_s=np.float64(90.0),
                      play=np.full(100, 500.0)))
    argv = ["versus", "--seeds", "0", "--agents", "ppo", "--out", str(tmp_path)]
    assert reproduce_main([*argv, "--stored-only"]) == 0
    assert "| PPO, rl-zoo3's hyperparameters (stable-baselines3) | 1 of 1 |" in \
        (tmp_path / "VERSUS.md").read_text()
    capsys.readouterr()
    assert reproduce_main(argv) == 2
    assert "need the baselines extra" in capsys.readouterr().err.strip().splitlines()[-1]


def as_in_a_terminal() -> None:
    """A terminal's foreground process takes SIGINT. One started by a process that ignores it
    (a job a script put in the background: pytest's, and its workers', in such a suite run)
    inherits the ignoring, and Python then sets no KeyboardInterrupt: Ctrl-C did nothing."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("stop, to_group, code, line", [
    (signal.SIGINT, True, 130, "interrupted"),  # Ctrl-C: the terminal's whole process group
    (signal.SIGTERM, False, 143, "terminated"),  # kill PID: the main process alone
])
def test_versus_stopped_ends_at_once_in_one_line_and_keeps_what_was_stored(tmp_path, stop,
                                                                          to_group, code, line):
    """Ctrl-C or SIGTERM: exit 130 or 143 with one line, no worker left running (SIGTERM to
    the main process alone once left them computing, orphaned), every agent-seed stored before
    it readable."""
    stored = tmp_path / "data" / "versus" / "ase_ace"
    run = subprocess.Popen([sys.executable, "-m", "clnn_ros.reproduce", "versus", "--agents",
                            "ase_ace", "--seeds", "0-999", "--workers", "2", "--out",
                            str(tmp_path)], stderr=subprocess.PIPE, text=True,
                           start_new_session=True, preexec_fn=as_in_a_terminal)
    try:
        deadline = time.monotonic() + HANG_S
        while len(list(stored.glob("*.npz"))) < 2 and run.poll() is None:
            assert time.monotonic() < deadline, "no agent-seed stored"
            time.sleep(0.2)
        (os.killpg if to_group else os.kill)(run.pid, stop)
        _, err = run.communicate(timeout=HANG_S)
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
    try:
        assert run.returncode == code, err
        assert [text for text in err.splitlines() if text.strip()] == [line], err
        kept = list(stored.glob("*.npz"))
        assert 2 <= len(kept) < 1000
        assert all(len(load_stored(path)["returns"]) > 0 for path in kept)
        with pytest.raises(ProcessLookupError):  # the workers too: none of the group is left
            for _ in range(int(HANG_S / 0.1)):
                os.killpg(run.pid, 0)
                time.sleep(0.1)
    finally:  # a failed test leaves no orphaned worker behind
        with contextlib.suppress(ProcessLookupError):
            os.killpg(run.pid, signal.SIGKILL)


@pytest.mark.parametrize("agents, message", [
    ("rln,a2c", "unknown agent 'a2c'; known: rln, rln_mujoco, ase_ace, ppo, dqn, dqn_4x"),
])
def test_versus_refuses_an_unknown_agent_in_one_line(tmp_path, capsys, agents, message):
    assert reproduce_main(["versus", "--agents", agents, "--out", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err.strip().splitlines()[-1]
    assert not (tmp_path / "VERSUS.md").exists()
