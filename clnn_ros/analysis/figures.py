"""The pictures of `python -m clnn_ros.analysis`, drawn from what a bag holds (matplotlib, Agg).

Each *_figure function takes arrays and returns its Figure (the tests inspect them); save() writes
one as PNG, animate_trial() writes a GIF. The paper's figures are clnn_ros.figures' (reproduce);
these share its colours and its way of saving.

    series         one trial (TrialSeries) and what its pictures share
    trial_figures  a trial's traces and spike raster
    animation      the cart-pole's GIF of a trial
    here           the learning curve (the cart-pole's, any task's) and the weights
"""

from __future__ import annotations

import numpy as np
from matplotlib.ticker import MaxNLocator

from ..figures import END_COLORS, END_LABELS, _save as save, plt
from ..graph.fields import END_REASONS
from .animation import GIF_DPI, GIF_FPS, GIF_FRAMES, animate_trial, frame_indices
from .series import (ACTION_TICKS, HISTORY_SEGMENTS, NEAR_LIMIT, OVERVIEW_BINS,
                     OVERVIEW_MIN_TICKS, WINDOW_TICKS, TrialSeries, bin_width, binned_mean,
                     column_starts, mark_reinforcement, neuron_name, right_edge)
from .trial_figures import draw_overview, raster_figure, traces_figure

__all__ = ["save", "plt", "TrialSeries", "learning_curve_figure", "task_learning_curve_figure",
           "weights_figure", "weights_history_figure", "segment_ranges_figure", "traces_figure",
           "raster_figure", "draw_overview", "animate_trial", "frame_indices", "bin_width",
           "binned_mean", "column_starts", "mark_reinforcement", "neuron_name", "right_edge",
           "GIF_DPI", "GIF_FPS", "GIF_FRAMES", "ACTION_TICKS", "HISTORY_SEGMENTS", "NEAR_LIMIT",
           "OVERVIEW_BINS", "OVERVIEW_MIN_TICKS", "WINDOW_TICKS"]
# A weights picture writes each weight's value in its cell up to this many segments; beyond
# (another task's many segments), colours alone, in rows of at most WEIGHT_ROWS_IN inches.
NUMBERED_SEGMENTS = 16
WEIGHT_ROWS_IN = 6.0
END_MAP = "tab10"  # another task's trial ends: a colour each


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


def task_learning_curve_figure(rows, max_steps: int, title: str, end_labels: dict[str, str],
                               returns: dict[int, float] | None = None,
                               threshold: float | None = None):
    """Any task's: successful steps per trial, each point coloured by how the trial ended
    (`end_labels`: each end reason's legend, in their order); below, given each trial's return
    (the sum of its observations' rewards), the return per trial and the task's own "solved"
    threshold where it has one."""
    panels = 2 if returns else 1
    fig, axes = plt.subplots(panels, 1, figsize=(9, 3.8 + 2.6 * (panels - 1)), sharex=True,
                             constrained_layout=True, squeeze=False)
    ax = axes[0, 0]
    trials = np.array([r[1] for r in rows])
    steps = np.array([r[3] for r in rows])
    ends = [r[4] for r in rows]
    labels = dict(end_labels)
    labels.update({end: end for end in ends if end not in labels})
    colors = plt.get_cmap(END_MAP).colors
    ax.plot(trials, steps, color="tab:gray", linewidth=0.8)
    for k, (end, label) in enumerate(labels.items()):
        mask = np.array([e == end for e in ends])
        if mask.any():
            ax.scatter(trials[mask], steps[mask], s=18, color=colors[k % len(colors)],
                       label=label, zorder=3)
    ax.axhline(max_steps, color="black", linestyle="--", linewidth=0.8,
               label=f"step cap {max_steps:,}")
    ax.set_ylabel("successful steps")
    ax.set_ylim(0, max_steps * 1.25)
    ax.set_title(title)
    ax.legend(fontsize=8, loc="upper left", ncol=2)
    if returns:
        ax = axes[1, 0]
        ax.plot(trials, [returns.get(t, np.nan) for t in trials], color="tab:purple",
                linewidth=0.9, marker="o" if len(trials) <= 60 else None, markersize=3)
        if threshold is not None:
            ax.axhline(threshold, color="black", linestyle=":", linewidth=0.9,
                       label=f"the task's solved threshold {threshold:g}")
            ax.legend(fontsize=8, loc="best")
        ax.set_ylabel("return (sum of rewards)")
        ax.grid(alpha=0.3, linewidth=0.5)
    axes[-1, 0].set_xlabel("trial")
    axes[-1, 0].xaxis.set_major_locator(MaxNLocator(integer=True))
    return fig


def weights_figure(weights: np.ndarray, labels: list[str], w_max: float, title: str,
                   first: np.ndarray | None = None, first_trial: int | None = None,
                   action_labels=None):
    """Each neuron's weights (segments x inputs) on one colour scale, 0 to w_max, with the
    values written in (up to NUMBERED_SEGMENTS segments); below them, given the first snapshot
    (after `first_trial`), each weight's change since then on a scale of its own. Segments
    numbered from 0 as the messages do; neurons named by their actions (`action_labels`, None:
    the cart-pole's -F and +F)."""
    neurons, segments, inputs = weights.shape
    numbered = segments <= NUMBERED_SEGMENTS
    cell, row_in = (0.8, 1.1 + 0.36 * segments) if numbered else \
        (0.3, min(1.1 + 0.05 * segments, WEIGHT_ROWS_IN))
    every = 1 if numbered else -(-segments // 16)  # a label on every k-th segment
    rows = [(weights, "viridis", (0, w_max), f"weight (0 to w_max = {w_max:g})", "{:.3f}", "")]
    if first is not None:
        reach = max(float(np.abs(weights - first).max()), 1e-6)
        rows.append((weights - first, "RdBu_r", (-reach, reach),
                     f"change since trial {first_trial}", "{:+.3f}",
                     f": change since the snapshot after trial {first_trial}"))
    fig, axes = plt.subplots(len(rows), neurons, squeeze=False, sharex=True,
                             constrained_layout=True,
                             figsize=(1.8 + cell * inputs * neurons,
                                      0.9 + row_in * len(rows) + 1.1))
    for row, (values, cmap, (low, high), scale, number, caption) in enumerate(rows):
        for neuron, ax in enumerate(axes[row]):
            image = ax.imshow(values[neuron], cmap=cmap, vmin=low, vmax=high, aspect="auto")
            for (segment, i), value in np.ndenumerate(values[neuron] if numbered else []):
                red, green, blue, _ = image.cmap(image.norm(value))
                ax.text(i, segment, number.format(value), ha="center", va="center",
                        fontsize=6.5, color="black" if 0.299 * red + 0.587 * green +
                        0.114 * blue > 0.5 else "white")
            ax.set_yticks(range(0, segments, every),
                          [str(s) for s in range(0, segments, every)], fontsize=7)
            ax.set_ylabel("segment")
            ax.set_title(neuron_name(neuron, action_labels) + caption, fontsize=9)
        fig.colorbar(image, ax=axes[row].tolist(), label=scale, fraction=0.04, pad=0.02)
    for ax in axes[-1]:
        ax.set_xticks(range(inputs), labels, rotation=40, ha="right", rotation_mode="anchor",
                      fontsize=7)
        ax.set_xlabel("input (the encoder's interval)")
    fig.suptitle(title)
    return fig


def weights_history_figure(trials: np.ndarray, history: np.ndarray, labels: list[str],
                           title: str, action_labels=None):
    """Every weight over the run: one panel per neuron and segment, one line per input, a point
    per snapshot (history: snapshots x neurons x segments x inputs, after trial `trials`); of
    more than HISTORY_SEGMENTS segments, one panel per neuron, a line per input: its mean over
    the segments, their range shaded."""
    _, neurons, segments, inputs = history.shape
    if segments > HISTORY_SEGMENTS:
        return segment_ranges_figure(trials, history, labels, title, action_labels)
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
        ax.set_title(f"{neuron_name(neuron, action_labels)}, segment {segment}", fontsize=8)
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




def segment_ranges_figure(trials: np.ndarray, history: np.ndarray, labels: list[str],
                          title: str, action_labels=None):
    """weights_history_figure of many segments: a panel per neuron, a line per input (its mean
    over the segments), the range of all the neuron's weights shaded."""
    _, neurons, segments, inputs = history.shape
    fig, axes = plt.subplots(1, neurons, squeeze=False, sharey=True,
                             figsize=(4.2 * neurons + 2.6, 3.6), constrained_layout=True)
    colors = plt.get_cmap("tab10").colors if inputs <= 10 else \
        plt.get_cmap("turbo")(np.linspace(0, 1, inputs))
    marker = "o" if len(trials) <= 40 else None
    for neuron, ax in enumerate(axes[0]):
        weights = history[:, neuron].reshape(len(trials), -1)
        ax.fill_between(trials, weights.min(axis=1), weights.max(axis=1), color="0.88",
                        linewidth=0, label="range of all its weights")
        for i in range(inputs):
            ax.plot(trials, history[:, neuron, :, i].mean(axis=1), color=colors[i],
                    linewidth=0.9, marker=marker, markersize=2.5, label=labels[i])
        ax.set_title(f"{neuron_name(neuron, action_labels)}: each input's mean over "
                     f"{segments} segments", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3, linewidth=0.5)
        ax.set_xlabel("after trial")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    axes[0, 0].set_ylabel("weight", fontsize=8)
    handles, names = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside right upper", fontsize=7, title="input",
               title_fontsize=8)
    fig.suptitle(title)
    return fig
