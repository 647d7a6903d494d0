"""Checkpoint and resume: an episode split at a trial boundary equals the uninterrupted one, in
the core and in the real ROS graph (the cart-pole and a Gymnasium task); run_all --init-weights
refuses bad files, and a task that cannot resume, with one line before any node starts; fig7
weights in the graph equal the core; the agent's save service."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clnn_ros.core.agent import RLNAgent, SuccessCounter
from clnn_ros.core.checkpoint import (FORMAT, CheckpointError, capture, load_checkpoint,
                                      save_checkpoint)
from clnn_ros.core.episode import run_episode, seed_setup
from clnn_ros.core.optimal import optimal_weights
from clnn_ros.core.params import ParamError, Params
from clnn_ros.core.physics import CONTINUE
from clnn_ros.core.init_weights import EpisodeStart, episode_start, load_weights
from clnn_ros.core.task_episode import run_task_episode
from clnn_ros.tasks.gymnasium_task import (KNOWN, PREFIX, GymnasiumTaskEnvironment,
                                           check_resumable, make, task_params)

from conftest import free_domain_id, ros_environment
from test_graph import run_all

DOMAIN_ID = free_domain_id()
SEED = 1
# tie_break=random and success_counter=carry: the random stream and the success count cross
# trial boundaries, so a resume must restore them too
CARRY = {"tie_break": "random", "success_counter": "carry"}
CARRY_OPTIONS = ["--option", "tie_break=random", "--option", "success_counter=carry"]


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)




def read_rows(out: Path) -> list[str]:
    return (out / "trials.csv").read_text().splitlines()[1:]


@pytest.mark.parametrize("p", [Params(trials=16, max_steps=1500),
                               Params(nsv=2, velocity_edge=0.3, trials=16, max_steps=1500),
                               Params(trials=16, max_steps=1500, **CARRY)],
                         ids=["1sv", "2sv", "random_tie_break_carried_count"])
def test_core_split_episode_equals_the_whole(tmp_path, p):
    whole = run_episode(SEED, p)
    first = run_episode(SEED, p.replace(trials=8))
    checkpoint = load_checkpoint(save_checkpoint(tmp_path / "checkpoint.npz", first.checkpoint))
    assert checkpoint.next_trial == 8 and checkpoint.params == p.replace(trials=8)
    rest = run_episode(SEED, p, resume=checkpoint)
    np.testing.assert_array_equal(np.concatenate([first.steps, rest.steps]), whole.steps)
    np.testing.assert_array_equal(rest.initial_angles, whole.initial_angles[8:])
    np.testing.assert_array_equal(rest.final_weights, whole.final_weights)
    assert rest.checkpoint.agent.keys() == whole.checkpoint.agent.keys()
    for name, value in whole.checkpoint.agent.items():
        np.testing.assert_array_equal(rest.checkpoint.agent[name], value)


def test_core_resume_needs_the_random_stream_and_the_carried_count():
    """Without them the continuation differs: the split test above would notice a lost field."""
    p = Params(trials=16, max_steps=1500, **CARRY)
    first = run_episode(SEED, p.replace(trials=8)).checkpoint
    rest = run_episode(SEED, p, resume=first)
    fresh_stream = dict(first.agent, random_state=np.array([SEED], dtype=np.uint64))
    for changed in ({"agent": fresh_stream}, {"success_count": 0}):
        other = run_episode(SEED, p, resume=dataclasses.replace(first, **changed))
        assert not (np.array_equal(other.steps, rest.steps)
                    and np.array_equal(other.final_weights, rest.final_weights)), changed


def test_init_weights_sources(tmp_path):
    p = Params(trials=4, max_steps=400, **CARRY)
    np.testing.assert_array_equal(episode_start("fig7", SEED, p).weights, optimal_weights(1))
    np.testing.assert_array_equal(episode_start("fig12", SEED, Params(nsv=2)).weights,
                                  optimal_weights(2))
    assert episode_start("", SEED, p) == EpisodeStart()  # the seed's weights
    episode = run_episode(SEED, p)
    np.save(tmp_path / "w.npy", episode.final_weights)
    start = episode_start(str(tmp_path / "w.npy"), SEED, p)
    np.testing.assert_array_equal(start.weights, episode.final_weights)
    assert start.first_trial == 0 and start.success_counter(p).count == 0
    # what the reward node and the trial manager take from a checkpoint, without an agent
    save_checkpoint(tmp_path / "c.npz", episode.checkpoint)
    resumed = episode_start(str(tmp_path / "c.npz"), SEED, p.replace(trials=8))
    assert resumed.weights is None and resumed.first_trial == 4
    assert resumed.success_counter(p).count == episode.checkpoint.success_count > 0
    np.save(tmp_path / "big.npy", episode.final_weights + 8)
    with pytest.raises(CheckpointError, match=r"values must lie in \[0, w_max=8\]"):
        load_weights(str(tmp_path / "big.npy"), p)


def bad_files(tmp: Path) -> list[tuple[list[str], str]]:
    """(run_all arguments, the error it must print) for files and names that do not fit."""
    checkpoint = run_episode(SEED, Params(trials=4, max_steps=300)).checkpoint
    good = str(save_checkpoint(tmp / "good.npz", checkpoint))
    (tmp / "corrupt.npz").write_bytes(b"PK\x03\x04 not really a zip")
    np.savez(tmp / "other.npz", weights=checkpoint.weights)
    np.savez(tmp / "future.npz", format=FORMAT, format_version=99)
    np.save(tmp / "wrong_shape.npy", np.zeros((2, 9, 9)))
    return [
        ([str(tmp / "missing.npz")], "missing.npz: no such file"),
        ([str(tmp / "corrupt.npz")], "not a readable .npz file"),
        ([str(tmp / "other.npz")], "not a clnn_ros checkpoint"),
        ([str(tmp / "future.npz")], "format version 99, this clnn_ros reads version 1"),
        ([good, "--trials", "8", "--max-steps", "1000"],
         "saved with max_steps=300 (this run: 1000)"),
        ([good, "--trials", "8", "--seed", "5"], "continues seed 1, this run has seed 5"),
        ([good], "after the episode's trials=4: nothing left to run"),
        ([str(tmp / "wrong_shape.npy")], "this run's network needs numbers of shape (2, 3, 6)"),
        (["fig12"], "fig12 weights are for nsv=2"),
        (["weights.txt"], "init_weights must be fig7, fig12, a weights .npy or a checkpoint"),
    ]


@pytest.mark.ros
def test_bad_init_weights_stop_run_all_before_any_node_starts(ros_env, tmp_path):
    for args, message in bad_files(tmp_path):
        result = run_all(ros_env, "--no-record", "--init-weights", *args, timeout=30)
        assert result.returncode == 2, (args, result.stderr)
        assert result.stderr.startswith("run_all: error: ") and message in result.stderr, args
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert "run_all: seed" not in result.stdout  # printed just before the nodes start


@pytest.mark.ros
def test_graph_resumed_episode_equals_the_uninterrupted_one(ros_env, tmp_path):
    """12 trials in one run == 6 trials, then a resume from <out>/checkpoint.npz to 12 (in
    separate processes, then composed); with the random tie-break and a carried success count."""
    whole, first, rest = tmp_path / "whole", tmp_path / "first", tmp_path / "rest"
    common = ["--seed", str(SEED), "--max-steps", "1500", "--no-record", *CARRY_OPTIONS]
    for out, args in ((whole, [*common, "--trials", "12", "--composed"]),
                      (first, [*common, "--trials", "6"]),
                      (rest, ["--init-weights", str(first / "checkpoint.npz"), "--trials", "12",
                              "--composed"])):
        result = run_all(ros_env, *args, "--out", str(out))
        assert result.returncode == 0, result.stderr
    assert "resuming" in result.stdout and "at trial 7 of 12" in result.stdout
    assert read_rows(first) + read_rows(rest) == read_rows(whole)
    assert len(read_rows(rest)) == 6
    np.testing.assert_array_equal(np.load(rest / "final_weights.npy"),
                                  np.load(whole / "final_weights.npy"))
    core = run_episode(SEED, Params(trials=12, max_steps=1500, **CARRY))
    assert [int(row.split(",")[3]) for row in read_rows(whole)] == core.steps.tolist()
    assert load_checkpoint(rest / "checkpoint.npz").next_trial == 12


RESUMED_RUNS = {
    # protocol and max_steps are not the network's: once lost in the checkpoint, the resumed
    # trials ran the paper's protocol
    "cartpole_v1_protocol": (["--protocol", "gymnasium", "--max-steps", "500"], 4, 8),
    # its environment makes the resets before the resumed trial again
    "inverted_pendulum": (["--env", "gymnasium:InvertedPendulum-v5", "--max-steps", "200"], 3, 6),
}


@pytest.mark.ros
@pytest.mark.parametrize("name", RESUMED_RUNS)
def test_graph_resume_runs_the_saved_episodes_parameters(ros_env, tmp_path, name):
    """First trials in 5 processes, the rest resumed (composed) from the checkpoint alone: the
    trials and final weights of the core's uninterrupted episode."""
    args, split, trials = RESUMED_RUNS[name]
    first, rest = tmp_path / "first", tmp_path / "rest"
    for out, run_args in (
            (first, [*args, "--seed", str(SEED), "--trials", str(split)]),
            (rest, ["--init-weights", str(first / "checkpoint.npz"), "--trials", str(trials),
                    "--composed"])):
        result = run_all(ros_env, *run_args, "--no-record", "--out", str(out))
        assert result.returncode == 0, result.stderr
    rows = [row.split(",") for row in read_rows(first) + read_rows(rest)]
    if name == "inverted_pendulum":
        task, env = make("gymnasium:InvertedPendulum-v5")
        core = run_task_episode(SEED, task_params(task, {"trials": str(trials),
                                                         "max_steps": "200"}), task, env)
        expected = (core.steps - core.terminated).tolist()  # the graph's successful steps
    else:
        core = run_episode(SEED, Params(protocol="gymnasium", max_steps=500, trials=trials))
        expected = core.steps.tolist()
    assert [int(row[3]) for row in rows] == expected
    assert len({row[3] for row in rows}) > 1  # the trials' starts differ, and the steps show it
    np.testing.assert_array_equal(np.load(rest / "final_weights.npy"), core.final_weights)


def test_a_task_environment_starts_a_resumed_trial_as_the_uninterrupted_episode_does():
    """Its trial k: the seeded reset and k more, as many as the episode made before it (steps in
    between draw nothing in the families check_resumable lets resume)."""
    params = task_params(make("gymnasium:Acrobot-v1")[0])
    played = GymnasiumTaskEnvironment(params)
    for trial in range(3):
        start = played.start(SEED, trial, 0.0)
        for action in (0, 2, 1, 2):
            played.step(action)
    np.testing.assert_array_equal(GymnasiumTaskEnvironment(params).start(SEED, 2, 0.0), start)


@pytest.mark.parametrize("identifier", sorted(KNOWN))
def test_check_resumable_knows_whose_steps_draw(identifier):
    """The families check_resumable lets resume never move the random stream in step();
    LunarLander's steps do, and it is refused in one line."""
    task, env = make(PREFIX + identifier)
    env.reset(SEED)  # a seeded reset makes the stream anew
    stream = env.env.unwrapped.np_random.bit_generator
    before = stream.state
    for action in range(len(task.actions)):
        env.step(action)
    if identifier == "LunarLander-v3":
        assert stream.state != before
        with pytest.raises(ParamError, match="cannot resume from a checkpoint: its steps may "
                                             "draw from its random stream"):
            check_resumable(PREFIX + identifier)
    else:
        assert stream.state == before
        check_resumable(PREFIX + identifier)


def test_a_task_that_cannot_resume_is_refused_before_any_node_starts(ros_env, tmp_path):
    params = task_params(make("gymnasium:LunarLander-v3")[0], {"trials": "2"})
    agent = RLNAgent(params, seed_setup(SEED, params)[0], seed=SEED)
    path = save_checkpoint(tmp_path / "c.npz", capture(agent, SuccessCounter(params), SEED, 1))
    result = run_all(ros_env, "--no-record", "--init-weights", str(path), "--trials", "3",
                     timeout=30)
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("run_all: error: gymnasium:LunarLander-v3 cannot resume")
    assert len(result.stderr.strip().splitlines()) == 1 and "run_all: seed" not in result.stdout


@pytest.mark.ros
def test_graph_fig7_weights_equal_the_core_and_the_save_service(ros_env, tmp_path):
    """A new episode from the Figure 7 weights, learning on, equals the core's (true physics:
    the pole falls now and then, so the weights learn); during it the agent's service saves a
    checkpoint whose tick matches its trial and step."""
    trials, seed = 30, 2
    p = Params(trials=trials, physics="correct")
    run = subprocess.Popen(
        [sys.executable, "-m", "clnn_ros.run_all", "--init-weights", "fig7", "--seed", str(seed),
         "--trials", str(trials), "--physics", p.physics, "--no-record", "--out", str(tmp_path)],
        env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    while "trial    1/" not in (line := run.stdout.readline()):
        assert line, run.communicate()[1]
    saved = subprocess.run([sys.executable, "-m", "clnn_ros.live.save_checkpoint"], env=ros_env,
                           capture_output=True, text=True, timeout=30, check=False)
    _, stderr = run.communicate(timeout=120)
    assert run.returncode == 0, stderr
    assert saved.returncode == 0, saved.stderr
    core = run_episode(seed, p, weights=optimal_weights(1))
    assert [int(row.split(",")[3]) for row in read_rows(tmp_path)] == core.steps.tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), core.final_weights)
    assert not np.array_equal(core.final_weights, optimal_weights(1))  # it learned
    path = Path(saved.stdout.strip())
    checkpoint = load_checkpoint(path)
    assert path.parent == tmp_path and path.name == f"checkpoint_{checkpoint.tick}.npz"
    assert 1 <= checkpoint.next_trial < trials
    # a trial's ticks: its successful steps, its first tick, and its failing step if it failed;
    # trial_step ticks of the next one are done
    done = (core.steps + 1 + (core.end_status != CONTINUE))[:checkpoint.next_trial]
    assert checkpoint.tick == done.sum() + checkpoint.trial_step - 1
