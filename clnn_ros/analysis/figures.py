"""The pictures of `python -m clnn_ros.analysis`, drawn from what a bag holds (matplotlib, Agg).

Each *_figure function takes arrays and returns its Figure (the tests inspect them); save() writes
one as PNG, animate_trial() writes a GIF. The paper's figures are clnn_ros.figures' (reproduce);
these share its colours and its way of saving.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..figures import END_COLORS, END_LABELS, _save as save, plt
from ..graph.fields import END_REASONS

WINDOW_TICKS = 200     # a raster window: at this width every tick stays a visible column
OVERVIEW_BINS = 400    # a whole trial in at most this many columns (a 10,000-tick one too)
# Ticks per overview column at least: several swings of a balanced pole (about 10 ticks each),
# so that a column's share of spikes does not alias with them.
OVERVIEW_MIN_TICKS = 25
ACTION_TICKS = 1000    # traces: up to here every action; beyond, a mean per column
NEAR_LIMIT = 0.6       # a failure limit is drawn when the motion reaches this share of it
GIF_FRAMES = 300       # longer trials are shown every k-th tick
GIF_FPS = 20
GIF_DPI = 80
REWARD_COLOR, PUNISH_COLOR, ACTION_COLOR = "tab:green", "tab:red", "tab:purple"
FORCE_LABELS = {-1: "-F", 0: "none", 1: "+F"}


@dataclass
class TrialSeries:
    """One trial as the bag holds it: one entry per tick that has a state message."""

    trial: int
    ticks: np.ndarray          # the run's tick numbers
    states: np.ndarray         # (ticks, 4): cart position m, cart velocity m/s, pole angle deg,
    #                            pole angular velocity deg/s
    spikes: np.ndarray         # (inputs, ticks): 1 where the input spiked
    input_labels: list[str]
    actions: np.ndarray        # force direction: -1, +1; 0 on the last tick (or no message)
    reinforcement: np.ndarray  # +1 reward, -1 punishment, 0 neither
    steps: int                 # successful steps
    end_reason: str


def neuron_name(neuron: int) -> str:
    """As the Action message numbers them: neuron 0 drives -F, neuron 1 +F."""
    return f"neuron {neuron} ({FORCE_LABELS[1 if neuron else -1]})"


def bin_width(ticks: int) -> int:
    """Ticks per overview column: `ticks` in at most OVERVIEW_BINS columns of at least
    OVERVIEW_MIN_TICKS."""
    return max(OVERVIEW_MIN_TICKS, math.ceil(ticks / OVERVIEW_BINS))


def column_starts(count: int, width: int) -> np.ndarray:
    """The first entry of each column of `width` entries (the last column may be shorter)."""
    return np.arange(0, count, width)


def binned_mean(values: np.ndarray, width: int) -> np.ndarray:
    """The mean of each column of `width` consecutive entries along the last axis."""
    count = values.shape[-1]
    starts = column_starts(count, width)
    sizes = np.diff(np.append(starts, count))
    return np.add.reduceat(values.astype(np.float64), starts, axis=-1) / sizes


def learning_curve_figure(rows, max_steps: int, title: str):
    """Successful steps per trial, each point coloured by how the trial ended."""
    fig, ax = plt.subplots(figsize=(9, 3.8), constrained_layout=True)
    trials = np.array([r[1] for r in rows])
    steps = np.array([r[3] for r in rows])
    codes = {reason: code for code, reason in enumerate(END_REASONS)}  # END_LABELS' order
    ends = np.array([codes.get(r[4], 1) for r in rows])
    ax.plot(trials, steps, color="tab:gray", linewidth=0.8)
    for code, label in END_LABELS.items():
        mask = ends == code
        if mask.any():
            ax.scatter(trials[mask], steps[mask], s=18, color=END_COLORS[code], label=label,
                       zorder=3)
    ax.axhline(max_steps, color="black", linestyle="--", linewidth=0.8,
               label=f"step cap {max_steps:,}")
    ax.set_xlabel("trial")
    ax.set_ylabel("successful steps")
    ax.set_ylim(0, max_steps * 1.25)
    ax.set_title(title)
    ax.legend(fontsize=8, loc="upper left", ncol=2)
    return fig


def weights_figure(weights: np.ndarray, labels: list[str], w_max: float, title: str,
                   first: np.ndarray | None = None, first_trial: int | None = None):
    """Each neuron's weights (segments x inputs) on one colour scale, 0 to w_max, with the
    values written in; below them, given the first snapshot (after `first_trial`), each weight's
    change since then on a scale of its own. Segments numbered from 0 as the messages do."""
    neurons, segments, inputs = weights.shape
    rows = [(weights, "viridis", (0, w_max), f"weight (0 to w_max = {w_max:g})", "{:.3f}", "")]
    if first is not None:
        reach = max(float(np.abs(weights - first).max()), 1e-6)
        rows.append((weights - first, "RdBu_r", (-reach, reach),
                     f"change since trial {first_trial}", "{:+.3f}",
                     f": change since the snapshot after trial {first_trial}"))
    fig, axes = plt.subplots(len(rows), neurons, squeeze=False, sharex=True,
                             constrained_layout=True,
                             figsize=(1.8 + 0.8 * inputs * neurons,
                                      0.9 + (1.1 + 0.36 * segments) * len(rows) + 1.1))
    for row, (values, cmap, (low, high), scale, number, caption) in enumerate(rows):
        for neuron, ax in enumerate(axes[row]):
            image = ax.imshow(values[neuron], cmap=cmap, vmin=low, vmax=high, aspect="auto")
            for (segment, i), value in np.ndenumerate(values[neuron]):
                red, green, blue, _ = image.cmap(image.norm(value))
                ax.text(i, segment, number.format(value), ha="center", va="center",
                        fontsize=6.5, color="black" if 0.299 * red + 0.587 * green +
                        0.114 * blue > 0.5 else "white")
            ax.set_yticks(range(segments), [str(s) for s in range(segments)], fontsize=7)
            ax.set_ylabel("segment")
            ax.set_title(neuron_name(neuron) + caption, fontsize=9)
        fig.colorbar(image, ax=axes[row].tolist(), label=scale, fraction=0.04, pad=0.02)
    for ax in axes[-1]:
        ax.set_xticks(range(inputs), labels, rotation=40, ha="right", rotation_mode="anchor",
                      fontsize=7)
        ax.set_xlabel("input (the encoder's interval)")
    fig.suptitle(title)
    return fig


def weights_history_figure(trials: np.ndarray, history: np.ndarray, labels: list[str],
                           title: str):
    """Every weight over the run: one panel per neuron and segment, one line per input, a point
    per snapshot (history: snapshots x neurons x segments x inputs, after trial `trials`)."""
    _, neurons, segments, inputs = history.shape
    fig, axes = plt.subplots(segments, neurons, squeeze=False, sharex=True, sharey=True,
                             figsize=(4.2 * neurons + 2.6, 0.5 + 1.3 * segments),
                             constrained_layout=True)
    colors = plt.get_cmap("tab10").colors if inputs <= 10 else \
        plt.get_cmap("turbo")(np.linspace(0, 1, inputs))
    marker = "o" if len(trials) <= 40 else None
    for (segment, neuron), ax in np.ndenumerate(axes):
        for i in range(inputs):
            ax.plot(trials, history[:, neuron, segment, i], color=colors[i], linewidth=0.9,
                    marker=marker, markersize=2.5, label=labels[i])
        ax.set_title(f"{neuron_name(neuron)}, segment {segment}", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3, linewidth=0.5)
    for ax in axes[-1]:
        ax.set_xlabel("after trial")
    for ax in axes[:, 0]:
        ax.set_ylabel("weight", fontsize=8)
    handles, names = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside right upper", fontsize=7, title="input",
               title_fontsize=8)
    fig.suptitle(title)
    return fig


def mark_reinforcement(ax, series: TrialSeries, low: float, high: float) -> None:
    """Rewards and punishments as coloured lines from `low` to `high` (data units)."""
    for value, color, label in ((1, REWARD_COLOR, "reward"), (-1, PUNISH_COLOR, "punishment")):
        at = series.ticks[series.reinforcement == value]
        if len(at):
            ax.vlines(at, low, high, color=color, linewidth=1.5, label=label, zorder=3)


def right_edge(ticks: np.ndarray) -> float:
    """The x limit past the last tick that keeps a mark on it (a punishment) clear of the
    frame."""
    return ticks[-1] + max(1.0, 0.01 * (ticks[-1] - ticks[0]))


def raster_figure(series: TrialSeries, title: str):
    """Spikes of a trial tick by tick: all of a trial of up to WINDOW_TICKS ticks; of a longer
    one its first and last WINDOW_TICKS, under an overview of all of it (the share of ticks each
    input spiked and the mean action, per column of k ticks). Reward and punishment marked."""
    inputs, count = series.spikes.shape
    windows = [(0, min(count, WINDOW_TICKS))]
    if count > WINDOW_TICKS:
        windows.append((count - WINDOW_TICKS, count))
    row = 0.24 * inputs + 0.4
    heights = ([row, 1.1] if len(windows) > 1 else []) + [row, 0.8]
    fig = plt.figure(figsize=(12, 1.0 + sum(heights)), constrained_layout=True)
    grid = fig.add_gridspec(len(heights), len(windows), height_ratios=heights)
    if len(windows) > 1:
        draw_overview(fig, grid, series, windows)
    for column, (start, end) in enumerate(windows):
        raster = fig.add_subplot(grid[-2, column])
        action = fig.add_subplot(grid[-1, column], sharex=raster)
        ticks = series.ticks[start:end]
        raster.imshow(series.spikes[:, start:end], aspect="auto", cmap="Greys", vmin=0, vmax=1,
                      interpolation="nearest",
                      extent=(ticks[0] - 0.5, ticks[-1] + 0.5, inputs - 0.5, -0.5))
        mark_reinforcement(raster, series, -0.5, inputs - 0.5)
        raster.set_yticks(range(inputs), series.input_labels if column == 0 else [],
                          fontsize=7)
        raster.set_title(f"all {count} ticks" if len(windows) == 1 else
                         f"{'first' if start == 0 else 'last'} {end - start} ticks (shaded "
                         f"above)", fontsize=9)
        if column == 0 and series.reinforcement[start:end].any():
            raster.legend(fontsize=7, loc="upper left")
        action.step(ticks, series.actions[start:end], where="mid", color=ACTION_COLOR,
                    linewidth=0.8)
        action.set_yticks([-1, 0, 1], ["-F", "none", "+F"] if column == 0 else [], fontsize=7)
        action.set_ylim(-1.3, 1.3)
        action.set_ylabel("action" if column == 0 else "", fontsize=8)
        action.set_xlabel("tick")
        action.set_xlim(ticks[0] - 0.5, right_edge(ticks))
    fig.suptitle(title)
    return fig


def draw_overview(fig, grid, series: TrialSeries, windows: list[tuple[int, int]]) -> None:
    """The raster's top rows: the share of ticks each input spiked and the mean action, per
    column of k ticks, with reward and punishment marked and the windows shaded."""
    overview = fig.add_subplot(grid[0, :])
    overview_action = fig.add_subplot(grid[1, :], sharex=overview)
    inputs, count = series.spikes.shape
    width = bin_width(count)
    columns = series.ticks[0] - 0.5 + np.append(column_starts(count, width), count)
    image = overview.pcolormesh(columns, np.arange(inputs + 1) - 0.5,
                                binned_mean(series.spikes, width), cmap="Greys", vmin=0, vmax=1)
    overview.invert_yaxis()  # input 0 on top, as in the windows
    overview.set_yticks(range(inputs), series.input_labels, fontsize=7)
    overview.set_title(f"whole trial ({count:,} ticks, {width} per column): share of ticks each "
                       f"input spiked", fontsize=9)
    fig.colorbar(image, ax=[overview, overview_action], fraction=0.02, pad=0.01,
                 label="share of ticks")
    overview_action.stairs(binned_mean(series.actions, width), columns, color=ACTION_COLOR,
                           linewidth=0.8, label="mean action", baseline=None)
    mark_reinforcement(overview_action, series, 1.15, 1.55)
    for start, end in windows:
        overview_action.axvspan(series.ticks[start], series.ticks[end - 1], color="0.85",
                                zorder=0)
    overview_action.set_yticks([-1, 0, 1], ["-F", "0", "+F"], fontsize=7)
    overview_action.set_ylim(-1.15, 1.6)
    overview_action.set_ylabel("action", fontsize=8)
    overview_action.set_xlim(columns[0], right_edge(series.ticks))
    overview_action.legend(fontsize=7, loc="lower left", ncol=3)


def traces_figure(series: TrialSeries, angle_limit: float, track_limit: float, title: str):
    """The state, the action and the reinforcement of a trial against the tick, each axis
    scaled to the motion (a failure limit drawn only where the motion comes near it)."""
    fig, axes = plt.subplots(6, 1, figsize=(11, 9.5), sharex=True, constrained_layout=True,
                             gridspec_kw={"height_ratios": [1, 1, 1, 1, 0.8, 0.45]})
    ticks = series.ticks
    width = bin_width(len(ticks))
    columns = np.append(ticks[::width], ticks[-1] + 1)  # a long trial's column edges
    panels = ((0, "cart position (m)", "tab:blue", track_limit, "m"),
              (1, "cart velocity (m/s)", "tab:cyan", None, ""),
              (2, "pole angle (deg)", "tab:red", angle_limit, "deg"),
              (3, "pole angular\nvelocity (deg/s)", "tab:orange", None, ""))
    for ax, (column, label, color, limit, unit) in zip(axes, panels):
        values = series.states[:, column]
        if len(ticks) <= ACTION_TICKS:
            ax.plot(ticks, values, color=color, linewidth=0.8)
        else:  # a line swinging every few ticks would fill its range solid: range and mean
            starts = column_starts(len(ticks), width)
            low, high = (np.append(extreme, extreme[-1]) for extreme in  # step="post"'s end
                         (np.minimum.reduceat(values, starts), np.maximum.reduceat(values, starts)))
            ax.fill_between(columns, low, high, step="post", color=color, alpha=0.35,
                            linewidth=0)
            ax.stairs(binned_mean(values, width), columns, color=color, linewidth=0.9,
                      baseline=None)
        ax.set_ylabel(label, fontsize=9)
        if limit is None:
            continue
        if np.abs(values).max() >= NEAR_LIMIT * limit:
            for sign in (1, -1):
                ax.axhline(sign * limit, color="gray", linestyle="--", linewidth=0.8,
                           label="failure limits" if sign == 1 else None)
            ax.legend(fontsize=7, loc="upper left")
        else:
            ax.set_title(f"failure limits ±{limit:g} {unit}: off this scale", loc="right",
                         fontsize=7, color="gray")
    action = axes[4]
    if len(ticks) <= ACTION_TICKS:
        action.step(ticks, series.actions, where="mid", color=ACTION_COLOR, linewidth=0.8)
        action.set_ylabel("action", fontsize=9)
    else:
        action.stairs(binned_mean(series.actions, width), columns, color=ACTION_COLOR,
                      linewidth=0.8, baseline=None)
        action.set_ylabel(f"action, mean\nof {width} ticks", fontsize=9)
        axes[0].set_title(f"per column of {width} ticks: the range (shaded) and the mean",
                          loc="left", fontsize=8)
    action.set_yticks([-1, 0, 1], ["-F", "0", "+F"])
    action.set_ylim(-1.15, 1.15)
    reward = axes[5]
    mark_reinforcement(reward, series, 0, 1)
    reward.set_yticks([0.5], ["reward /\npunishment"], fontsize=8)
    reward.set_ylim(0, 1)
    if series.reinforcement.any():
        reward.legend(fontsize=7, loc="upper left", ncol=2)
    else:
        reward.text(0.5, 0.5, "no reward or punishment in this trial", transform=reward.transAxes,
                    ha="center", va="center", fontsize=8, color="gray")
    reward.set_xlabel("tick")
    reward.set_xlim(ticks[0], right_edge(ticks))
    fig.suptitle(title)
    return fig


def frame_indices(count: int, frames: int = GIF_FRAMES) -> list[int]:
    """Every k-th tick, k chosen so that at most `frames` remain, and always the last (the
    trial's end)."""
    indices = list(range(0, count, max(1, math.ceil(count / frames))))
    if indices[-1] != count - 1:
        if len(indices) == frames:
            indices.pop()
        indices.append(count - 1)
    return indices


def animate_trial(series: TrialSeries, pole_length: float, track_limit: float, tau: float,
                  path: Path, progress: Callable[[int, int], None] | None = None) -> int:
    """A GIF of the cart and the pole (to scale; the pole is 2 x pole_length long) with the
    tick's spikes and action beside it. Returns the number of frames."""
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.patches import FancyArrowPatch, Rectangle

    inputs = len(series.input_labels)
    length = 2 * pole_length
    reach = min(max(1.0, np.abs(series.states[:, 0]).max() + 0.8), track_limit + 0.4)
    low, high = -0.15, 0.25 + 1.1 * length
    # inches: the track to scale (equal aspect) in at most 7 in, beside it the spikes (their
    # labels on their right) and the action
    width = min(7.0, 2.0 * 2 * reach / (high - low))
    height = width * (high - low) / (2 * reach)
    fig_width, fig_height = width + 3.4, max(height + 0.9, 0.22 * inputs + 0.9)
    fig = plt.figure(figsize=(fig_width, fig_height))

    def axes(left, bottom, ax_width, ax_height):  # in inches
        return fig.add_axes((left / fig_width, bottom / fig_height, ax_width / fig_width,
                             ax_height / fig_height))

    cart_ax = axes(0.25, 0.5, width, height)
    spike_ax = axes(width + 0.6, 0.3, 0.3, fig_height - 0.75)
    action_ax = axes(width + 2.55, fig_height / 2 - 0.4, 0.3, 0.8)
    cart_ax.set_xlim(-reach, reach)
    cart_ax.set_ylim(low, high)
    cart_ax.set_aspect("equal")
    cart_ax.axhline(0, color="black", linewidth=1)
    for sign in (1, -1):
        cart_ax.axvline(sign * track_limit, color=PUNISH_COLOR, linestyle="--", linewidth=0.8)
    cart_ax.set_yticks([])
    cart_ax.set_xlabel("cart position (m)", fontsize=8)
    cart_ax.tick_params(labelsize=7)
    cart = cart_ax.add_patch(Rectangle((0, 0), 0.4, 0.2, color="tab:blue"))
    (pole,) = cart_ax.plot([], [], color="tab:brown", linewidth=4, solid_capstyle="round")
    push = cart_ax.add_patch(FancyArrowPatch((0, 0), (0, 0), arrowstyle="-|>",
                                             mutation_scale=14, color=ACTION_COLOR))
    caption = fig.text(0.25 / fig_width, 1 - 0.3 / fig_height, "", fontsize=9)
    spikes = spike_ax.imshow(np.zeros((inputs, 1)), cmap="Greys", vmin=0, vmax=1,
                             aspect="auto")
    spike_ax.set_xticks([])
    spike_ax.set_yticks(range(inputs), series.input_labels, fontsize=7)
    spike_ax.yaxis.tick_right()
    spike_ax.set_title("spikes", fontsize=8)
    action = action_ax.imshow(np.zeros((2, 1)), cmap="Purples", vmin=0, vmax=1, aspect="auto")
    action_ax.set_xticks([])
    action_ax.set_yticks([0, 1], ["+F", "-F"], fontsize=8)
    action_ax.yaxis.tick_right()
    action_ax.set_title("action", fontsize=8)

    def draw(index: int):
        x, _, angle, _ = series.states[index]
        direction = int(series.actions[index])
        cart.set_x(x - 0.2)
        theta = math.radians(angle)
        pole.set_data([x, x + length * math.sin(theta)], [0.2, 0.2 + length * math.cos(theta)])
        push.set_positions((x, 0.1), (x + 0.45 * direction, 0.1))
        push.set_visible(direction != 0)
        spikes.set_data(series.spikes[:, index:index + 1])
        action.set_data(np.array([[direction == 1], [direction == -1]], dtype=float))
        last = index == len(series.ticks) - 1
        caption.set_text(f"trial {series.trial}, tick {series.ticks[index]:,} "
                         f"(t = {(series.ticks[index] - series.ticks[0]) * tau:.2f} s), "
                         f"angle {angle:+.2f} deg"
                         + (f"  - end: {series.end_reason}" if last else ""))

    indices = frame_indices(len(series.ticks))
    animation = FuncAnimation(fig, draw, frames=indices, blit=False, cache_frame_data=False)
    animation.save(path, writer=PillowWriter(fps=GIF_FPS), dpi=GIF_DPI,
                   progress_callback=progress)
    plt.close(fig)
    return len(indices)

