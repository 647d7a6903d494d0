"""The pictures of clnn_ros.analysis.analyze: the files it writes from the sample bag (valid PNGs,
a GIF of
the frames expected, summary.md naming them), the figures' contents checked on their matplotlib
objects (colour bar, the bag's labels, segments from 0, axes scaled to the motion, a raster that
stays readable at 10,000 ticks), refused arguments leaving nothing behind, and the environment
node kept in a bag by run_all (a ROS run)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clnn_ros.analysis import figures as pictures
from clnn_ros.analysis import analyze as analysis
from clnn_ros.analysis.data import metadata_record
from clnn_ros.analysis.summary import environment_lines
from clnn_ros.bag import open_bag
from clnn_ros.core.params import Params
from clnn_ros.core.task import Variable, cartpole_task
from clnn_ros.figures import plt

from conftest import HANG_S, free_domain_id, ros_environment

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "bags" / "sample_seed0_12trials"
LABELS = [f"pole_angle[{lo},{hi})deg" for lo, hi in
          (("-inf", -6), (-6, -1), (-1, 0), (0, 1), (1, 6), (6, "inf"))]
PNGS = ("learning_curve.png", "traces.png", "raster.png", "weights.png", "weights_history.png")
ANIMATED = 0  # the sample's trial 0: 34 ticks, 34 frames
CHOSEN = 11   # 769 ticks, ends at the cart position limit: an overview, two windows, a punishment
CARTPOLE = cartpole_task(Params()).variables  # the paper's limits: +-2.4 m, +-12 deg
# Another task's (Acrobot-v1's as Gymnasium describes it)
ACROBOT = tuple(Variable(name, unit, -bound, bound) for name, unit, bound in (
    ("cos_theta1", "", 1.0), ("sin_theta1", "", 1.0), ("cos_theta2", "", 1.0),
    ("sin_theta2", "", 1.0), ("theta1_dot", "rad/s", 12.566), ("theta2_dot", "rad/s", 28.274)))


def analyze(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "clnn_ros.analysis", *map(str, args)],
                          capture_output=True, text=True, timeout=HANG_S, cwd=cwd)


@pytest.fixture(scope="module")
def sample_analysis(tmp_path_factory):
    if not SAMPLE.exists():
        pytest.skip("no sample bag")
    out = tmp_path_factory.mktemp("sample") / "analysis"
    result = analyze(SAMPLE, "--out", out, "--trial", CHOSEN, "--animate", ANIMATED)
    assert result.returncode == 0, result.stderr
    return out


def series(ticks: int, amplitude: float = 0.1, start: int = 0) -> pictures.TrialSeries:
    """A synthetic trial: every state variable swinging with `amplitude`, an input spiking by
    the sign of the angle, actions alternating, a reward every 256 ticks, a punishment last."""
    phase = np.arange(ticks) * 2 * np.pi / 10
    wave = amplitude * np.sin(phase)
    spikes = np.zeros((6, ticks), dtype=np.uint8)
    spikes[np.where(wave < 0, 2, 3), np.arange(ticks)] = 1
    reinforcement = np.zeros(ticks, dtype=int)
    reinforcement[255::256] = 1
    reinforcement[-1] = -1
    return pictures.TrialSeries(
        trial=3, ticks=start + np.arange(ticks), states=np.stack([wave] * 4, axis=1),
        spikes=spikes, input_labels=LABELS, actions=np.where(wave < 0, 1, -1),
        reinforcement=reinforcement, steps=ticks - 1, end_reason="pole_angle",
        variables=CARTPOLE)


def acrobot_series(ticks: int) -> pictures.TrialSeries:
    """Another task's trial: six variables swinging, three actions by index (NaN: none on the
    last tick), as a bag of contract version 4 gives them."""
    wave = np.sin(np.arange(ticks) * 2 * np.pi / 10)
    actions = np.where(wave < -0.3, 0.0, np.where(wave > 0.3, 2.0, 1.0))
    actions[-1] = np.nan
    spikes = np.zeros((6, ticks), dtype=np.uint8)
    spikes[np.where(wave < 0, 0, 1), np.arange(ticks)] = 1
    return pictures.TrialSeries(
        trial=0, ticks=np.arange(ticks), states=np.stack([wave * k for k in (1, 1, 0.5, 0.5, 3, 6)],
                                                        axis=1),
        spikes=spikes, input_labels=LABELS, actions=actions,
        reinforcement=np.zeros(ticks, dtype=int), steps=ticks - 1, end_reason="max_steps",
        variables=ACROBOT, action_labels=("0", "1", "2"))


# --- the files --------------------------------------------------------------------------------

def test_every_picture_is_written_as_a_valid_image(sample_analysis):
    for name in PNGS:
        with Image.open(sample_analysis / name) as image:
            assert image.format == "PNG", name
            assert image.width >= 600 and image.height >= 250, (name, image.size)
    with Image.open(sample_analysis / f"trial_{ANIMATED}.gif") as gif:
        assert gif.format == "GIF" and gif.is_animated
        assert gif.n_frames == 34  # every tick of the 34-tick trial
        assert gif.width >= 400 and gif.height >= 120
    assert not list(sample_analysis.parent.glob(".analysis_*"))  # the staging folder is gone


def test_summary_names_the_run_and_every_picture(sample_analysis):
    summary = (sample_analysis / "summary.md").read_text()
    for name in (*PNGS, f"trial_{ANIMATED}.gif"):
        assert f"* `{name}`: " in summary, name
    assert "* environment: the built-in cart-pole node (`python -m clnn_ros.nodes.environment`)" \
        in summary
    assert "* physics: `paper` equations, `semi_implicit` integration (the built-in node's)" in \
        summary
    assert "* encoding: pole angle (1 state variable), 6 inputs: `pole_angle[-inf,-6)deg`" in \
        summary
    assert "* velocity edge: not used: 1 state variable encodes the pole angle only" in summary
    assert f"* `traces.png`: trial {CHOSEN} against the tick" in summary
    assert f"* `trial_{ANIMATED}.gif`: trial {ANIMATED}'s cart and pole" in summary
    assert f"## Trial {CHOSEN}" in summary


def test_environment_lines_name_the_node_and_its_physics():
    data = {"params": Params(nsv=2, velocity_edge=0.28), "record": {}}
    labels = [f"input {i}" for i in range(9)]
    for environment, node, physics in (
            ("cartpole", "the built-in cart-pole node", "`paper` equations"),
            ("gymnasium", "gymnasium's CartPole-v1 node", "gymnasium's CartPole-v1"),
            ("mujoco", "the MuJoCo cart-pole node", "MuJoCo's, with gymnasium CartPole-v1's"),
            ("external", "an external node", "the external node's own"),
            ("python my_env.py", "your own node: `python my_env.py`", "the node's own")):
        data["record"] = {"environment": environment}
        lines = environment_lines(data, labels)
        assert lines[0].startswith(f"* environment: {node}"), lines[0]
        assert lines[1].startswith(f"* physics: {physics}"), lines[1]
        assert lines[3] == "* velocity edge: 0.28 m/s (cart velocity intervals: below -e, " \
                           "[-e, e), e and above)"


# --- the figures ------------------------------------------------------------------------------

def colorbars(fig) -> list:
    return [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]


def test_weights_have_a_colour_bar_the_bags_labels_and_segments_from_0():
    rng = np.random.default_rng(0)
    final = 4.5 + rng.uniform(-0.5, 0.5, (2, 3, 6))
    fig = pictures.weights_figure(final, LABELS, 8.0, "weights", final - 0.1, 0)
    try:
        assert len(colorbars(fig)) == 2  # the weights' and their changes'
        panels = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
        assert len(panels) == 4
        weights_image = panels[0].get_images()[0]
        assert weights_image.get_clim() == (0, 8.0)
        for ax in panels:
            assert [t.get_text() for t in ax.get_yticklabels()] == ["0", "1", "2"]
        assert [t.get_text() for t in panels[-1].get_xticklabels()] == LABELS
        assert "neuron 0 (-F)" in panels[0].get_title()
        assert "change since the snapshot after trial 0" in panels[2].get_title()
    finally:
        plt.close(fig)


def test_weights_history_draws_every_weight_from_every_snapshot():
    history = 4.5 + np.cumsum(np.full((12, 2, 3, 6), 0.01), axis=0)
    fig = pictures.weights_history_figure(np.arange(12), history, LABELS, "history")
    try:
        assert len(fig.axes) == 2 * 3
        for ax in fig.axes:
            assert len(ax.get_lines()) == 6 and all(len(line.get_xdata()) == 12
                                                    for line in ax.get_lines())
        assert [t.get_text() for t in fig.legends[0].get_texts()] == LABELS
    finally:
        plt.close(fig)


def test_traces_follow_the_motion_in_ticks():
    for amplitude, limits_drawn in ((0.1, False), (2.3, True)):
        fig = pictures.traces_figure(series(500, amplitude), "traces")
        try:
            position, velocity, angle, _, action, reward = fig.axes
            low, high = position.get_ylim()
            if limits_drawn:
                assert low <= -2.4 and high >= 2.4
            else:
                assert -0.2 < low < -0.09 and 0.09 < high < 0.2  # the motion, not +-2.4 m
                assert "off this scale" in position.get_title(loc="right")
            assert velocity.get_ylim()[1] < 3 * amplitude
            assert reward.get_xlabel() == "tick"
            assert {c.get_label() for c in reward.collections} == {"reward", "punishment"}
            assert action.get_yticks().tolist() == [-1, 0, 1]
        finally:
            plt.close(fig)


def test_a_long_trial_is_drawn_by_columns():
    fig = pictures.traces_figure(series(10_001), "traces")
    try:
        assert "range (shaded) and the mean" in fig.axes[0].get_title(loc="left")
        assert all(len(ax.get_lines()) == 0 for ax in fig.axes[:4])  # no 10,000-point lines
    finally:
        plt.close(fig)


def test_raster_of_10000_ticks_has_an_overview_and_two_readable_windows():
    fig = pictures.raster_figure(series(10_001, start=500), "raster")
    try:
        overview = fig.axes[0]
        mesh = overview.collections[0]
        assert mesh.get_array().shape == (6, 385)  # 26 ticks per column: at most 400 columns
        windows = [ax for ax in fig.axes if ax.get_images()]
        assert len(windows) == 2
        for ax, first in zip(windows, (500, 500 + 10_001 - 200)):
            low, high = ax.get_xlim()
            assert low == first - 0.5 and 200 <= high - low <= 202
        labels = {c.get_label() for ax in fig.axes for c in ax.collections}
        assert {"reward", "punishment"} <= labels
    finally:
        plt.close(fig)


def test_raster_of_a_short_trial_is_one_window():
    fig = pictures.raster_figure(series(34), "raster")
    try:
        assert len([ax for ax in fig.axes if ax.get_images()]) == 1
        assert not any(ax.collections and ax.collections[0].get_array() is not None and
                       ax.collections[0].get_array().ndim == 2 for ax in fig.axes)
    finally:
        plt.close(fig)


def test_another_tasks_traces_have_a_panel_per_variable_and_its_actions():
    """A panel per variable, labelled with its name and unit; its bounds drawn where the motion
    comes near them; the action axis by the task's labels; a long trial's actions as the share
    of ticks each one took per column (no mean of unordered actions)."""
    fig = pictures.traces_figure(acrobot_series(500), "traces")
    try:
        *panels, action, reward = fig.axes
        assert [ax.get_ylabel() for ax in panels] == [
            "cos theta1", "sin theta1", "cos theta2", "sin theta2", "theta1 dot (rad/s)",
            "theta2 dot (rad/s)"]
        assert panels[0].get_legend() is not None  # +-1 reached: the bounds drawn
        assert "bounds ±12.566 rad/s: off this scale" == panels[4].get_title(loc="right")
        assert [t.get_text() for t in action.get_yticklabels()] == ["0", "1", "2"]
        assert "no reward or punishment" in reward.texts[0].get_text()
    finally:
        plt.close(fig)
    fig = pictures.traces_figure(acrobot_series(3000), "traces")
    try:
        action = fig.axes[6]
        shares = action.collections[0].get_array()
        assert shares.shape == (3, 120)  # actions x columns of 25 ticks
        assert np.allclose(shares.sum(axis=0)[:-1], 1.0)  # each column's ticks, all actions
        assert "share" in action.get_ylabel()
    finally:
        plt.close(fig)


def test_another_tasks_raster_labels_its_actions():
    fig = pictures.raster_figure(acrobot_series(1000), "raster")
    try:
        overview_action = fig.axes[1]
        assert [t.get_text() for t in overview_action.get_yticklabels()] == ["0", "1", "2"]
        assert overview_action.collections[0].get_array().shape == (3, 40)
        windows = [ax for ax in fig.axes if ax.get_ylabel() == "action" and ax.lines]
        assert [t.get_text() for t in windows[0].get_yticklabels()] == ["0", "1", "2"]
    finally:
        plt.close(fig)


def test_another_tasks_learning_curve_has_its_ends_and_returns():
    rows = [[0, trial, 0.0, steps, end] for trial, (steps, end) in
            enumerate([(500, "max_steps"), (310, "terminated"), (500, "max_steps")])]
    fig = pictures.task_learning_curve_figure(
        rows, 500, "curve", {"max_steps": "reached the step cap (truncated)",
                             "terminated": "terminated (success)"}, {0: -500.0, 1: -310.0,
                                                                     2: -500.0}, -100.0)
    try:
        steps, returns = fig.axes
        assert {t.get_text() for t in steps.get_legend().get_texts()} == {
            "reached the step cap (truncated)", "terminated (success)", "step cap 500"}
        assert returns.lines[0].get_ydata().tolist() == [-500.0, -310.0, -500.0]
        assert "solved threshold -100" in returns.get_legend().get_texts()[0].get_text()
    finally:
        plt.close(fig)


def test_weights_of_many_segments_stay_readable():
    """Another task's network (3 actions x 128 segments x 16 inputs): colours without numbers,
    at a bounded size, every 8th segment labelled; its history a panel per neuron (each input's
    mean over the segments), not 384 panels."""
    rng = np.random.default_rng(1)
    final = 4.5 + rng.uniform(-0.01, 0.01, (3, 128, 16))
    labels = [f"in{i}" for i in range(16)]
    fig = pictures.weights_figure(final, labels, 8.0, "weights", final - 0.001, 0,
                                  action_labels=("0", "1", "2"))
    try:
        width, height = fig.get_size_inches()
        assert width < 20 and height < 16
        panels = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
        assert len(panels) == 6 and not any(ax.texts for ax in panels)
        assert panels[0].get_yticks().tolist() == list(range(0, 128, 8))
        assert panels[0].get_title() == "neuron 0 (action 0)"
    finally:
        plt.close(fig)
    history = np.stack([final - 0.001, final])
    fig = pictures.weights_history_figure(np.arange(2), history, labels, "history",
                                          action_labels=("0", "1", "2"))
    try:
        assert len(fig.axes) == 3 and all(len(ax.get_lines()) == 16 for ax in fig.axes)
        assert "mean over 128 segments" in fig.axes[0].get_title()
    finally:
        plt.close(fig)


def test_frames_are_capped_and_keep_the_last_tick():
    assert pictures.frame_indices(34) == list(range(34))
    for count in (301, 2001, 10_001):
        frames = pictures.frame_indices(count)
        assert len(frames) <= pictures.GIF_FRAMES and frames[0] == 0
        assert frames[-1] == count - 1 and frames == sorted(set(frames))


def test_binned_mean_keeps_a_shorter_last_column():
    values = np.arange(7, dtype=float)
    assert pictures.binned_mean(values, 3).tolist() == [1.0, 4.0, 6.0]
    assert pictures.binned_mean(np.ones((2, 700), dtype=np.uint8), 300).tolist() == \
        [[1.0, 1.0, 1.0]] * 2


# --- refused arguments and failures leave nothing ------------------------------------------------

def test_refused_arguments_leave_nothing_behind(tmp_path):
    if not SAMPLE.exists():
        pytest.skip("no sample bag")
    (tmp_path / "a_file").write_text("")
    (tmp_path / "existing").mkdir()
    for args, message in (
            (["--trial", 99, "--out", tmp_path / "new" / "deep"], "--trial: trial 99 is not "
                                                                   "in the bag"),
            (["--animate", 99, "--out", tmp_path / "existing"], "--animate: trial 99 is not in "
                                                               "the bag"),
            (["--out", tmp_path / "a_file"], "is a file; expected a directory"),
            (["--out", tmp_path / "a_file" / "sub"], "is not a directory")):
        result = analyze(SAMPLE, *args)
        assert result.returncode == 2, result.stderr
        assert message in result.stderr and "Traceback" not in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a_file", "existing"]


def test_a_failure_while_writing_leaves_nothing(tmp_path):
    out = tmp_path / "new" / "analysis"
    with pytest.raises(RuntimeError):
        with analysis.staged_output(out) as folder:
            (folder / "trials.csv").write_text("half\n")
            raise RuntimeError("a picture failed")
    assert list(tmp_path.iterdir()) == []
    with analysis.staged_output(out) as folder:
        (folder / "trials.csv").write_text("all\n")
    assert [p.name for p in out.iterdir()] == ["trials.csv"]
    assert not list(out.parents[1].rglob(".analysis_*"))


# --- the environment node, kept in the bag ------------------------------------------------------

@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(free_domain_id(), tmp_path_factory)


@pytest.mark.ros
def test_a_run_with_its_own_environment_node_says_so(ros_env, tmp_path):
    command = "python examples/noisy_cartpole.py"
    run = subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--seed", "0",
                          "--trials", "2", "--max-steps", "100", "--env-node", command,
                          "--out", str(tmp_path / "run")], cwd=REPO, env=ros_env,
                         capture_output=True, text=True, timeout=HANG_S)
    assert run.returncode == 0, run.stderr
    reader, stream = open_bag(tmp_path / "run" / "bag")
    with stream:
        assert metadata_record(reader)["environment"] == command
    result = analyze(tmp_path / "run" / "bag", "--out", tmp_path / "analysis")
    assert result.returncode == 0, result.stderr
    summary = (tmp_path / "analysis" / "summary.md").read_text()
    assert f"* environment: your own node: `{command}` (`run_all --env-node`)" in summary
    assert "* physics: the node's own (the graph's parameter physics=paper" in summary
    assert "physics: `paper`" not in summary


@pytest.mark.parametrize("given, expected", [
    ("runs/bag", "runs/bag_analysis"),
    ("runs/my.bag", "runs/my.bag_analysis"),  # a directory: its whole name
    ("runs/bag/bag_0.mcap", "runs/bag_analysis"),  # beside the bag, never inside it
    ("runs/lone.mcap", "runs/lone_analysis"),
])
def test_default_out_is_beside_the_bag(tmp_path, given, expected):
    from clnn_ros.analysis.analyze import default_out
    bag_dir = tmp_path / "runs" / "bag"
    bag_dir.mkdir(parents=True)
    (bag_dir / "metadata.yaml").write_text("")
    (bag_dir / "bag_0.mcap").write_bytes(b"")
    (tmp_path / "runs" / "my.bag").mkdir()
    assert default_out(tmp_path / given) == tmp_path / expected
