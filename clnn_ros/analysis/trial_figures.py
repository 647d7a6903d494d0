"""The pictures of one trial (clnn_ros.analysis.figures): its traces against the tick (each of
the task's variables, the action, reward and punishment) and its spike raster. The cart-pole's
actions are drawn as its force direction (-F, +F); another task's by their labels, a long trial's
as the share of ticks each action took."""

from __future__ import annotations

import numpy as np

from ..figures import plt
from .series import (ACTION_COLOR, ACTION_TICKS, NEAR_LIMIT, WINDOW_TICKS, TrialSeries,
                     action_axis, action_shares, bin_width, binned_mean, column_starts,
                     mark_reinforcement, right_edge, variable_label)

# The cart-pole's panels, as they were drawn before any other task (labels and colours)
CARTPOLE_PANELS = {"cart_position": ("cart position (m)", "tab:blue"),
                   "cart_velocity": ("cart velocity (m/s)", "tab:cyan"),
                   "pole_angle": ("pole angle (deg)", "tab:red"),
                   "pole_angular_velocity": ("pole angular\nvelocity (deg/s)", "tab:orange")}
TRACE_COLORS = ("tab:blue", "tab:cyan", "tab:red", "tab:orange", "tab:green", "tab:brown",
                "tab:olive", "tab:pink", "tab:gray", "tab:purple")
SHARE_MAP = "Purples"  # another task's actions per column: the share of ticks each one took


def panel_of(series: TrialSeries, index: int) -> tuple[str, str]:
    """(label, colour) of a variable's panel."""
    variable = series.variables[index]
    if series.cartpole and variable.name in CARTPOLE_PANELS:
        return CARTPOLE_PANELS[variable.name]
    return variable_label(variable), TRACE_COLORS[index % len(TRACE_COLORS)]


def draw_bounds(ax, values: np.ndarray, low: float, high: float, unit: str, word: str) -> None:
    """A variable's finite bounds as dashed lines where the motion comes near one (NEAR_LIMIT of
    its distance from 0), else a note that they are off the scale."""
    bounds = [b for b in (high, low) if np.isfinite(b)]
    if not bounds:
        return
    reach = max(values.max(), 0.0), max(-values.min(), 0.0)
    if any(b and (reach[0] if b > 0 else reach[1]) >= NEAR_LIMIT * abs(b) for b in bounds):
        for k, bound in enumerate(bounds):
            ax.axhline(bound, color="gray", linestyle="--", linewidth=0.8,
                       label=word if k == 0 else None)
        ax.legend(fontsize=7, loc="upper left")
        return
    unit = f" {unit}" if unit else ""
    span = f"±{high:g}{unit}" if low == -high else f"{low:g} to {high:g}{unit}"
    ax.set_title(f"{word} {span}: off this scale", loc="right", fontsize=7, color="gray")


def traces_figure(series: TrialSeries, title: str):
    """The state, the action and the reinforcement of a trial against the tick: a panel per
    variable of the task, each axis scaled to the motion (a bound drawn only where the motion
    comes near it: the cart-pole's failure limits)."""
    count = len(series.variables)
    height = 9.5 * (count + 1.25) / 5.25 if count <= 8 else 1.3 * (count + 1.25)
    fig, axes = plt.subplots(count + 2, 1, figsize=(11, height), sharex=True,
                             constrained_layout=True,
                             gridspec_kw={"height_ratios": [1] * count + [0.8, 0.45]})
    ticks = series.ticks
    width = bin_width(len(ticks))
    columns = np.append(ticks[::width], ticks[-1] + 1)  # a long trial's column edges
    word = "failure limits" if series.cartpole else "bounds"
    for column, ax in enumerate(axes[:count]):
        label, color = panel_of(series, column)
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
        variable = series.variables[column]
        draw_bounds(ax, values, variable.low, variable.high, variable.unit, word)
    action = axes[count]
    draw_trace_action(action, series, width, columns)
    if len(ticks) > ACTION_TICKS:
        axes[0].set_title(f"per column of {width} ticks: the range (shaded) and the mean",
                          loc="left", fontsize=8)
    reward = axes[count + 1]
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


def draw_trace_action(action, series: TrialSeries, width: int, columns: np.ndarray) -> None:
    """The traces' action panel: every action up to ACTION_TICKS; beyond, per column, the
    cart-pole's mean force direction or the share of ticks each of another task's actions
    took."""
    ticks = series.ticks
    values, labels, low, high = action_axis(series)
    if len(ticks) <= ACTION_TICKS:
        action.step(ticks, series.actions, where="mid", color=ACTION_COLOR, linewidth=0.8)
        action.set_ylabel("action", fontsize=9)
    elif series.cartpole:
        action.stairs(binned_mean(series.actions, width), columns, color=ACTION_COLOR,
                      linewidth=0.8, baseline=None)
        action.set_ylabel(f"action, mean\nof {width} ticks", fontsize=9)
    else:
        action.pcolormesh(columns, np.arange(len(labels) + 1) - 0.5,
                          action_shares(series, width), cmap=SHARE_MAP, vmin=0, vmax=1)
        action.set_ylabel(f"action, share\nof {width} ticks", fontsize=9)
    action.set_yticks(values, labels)
    action.set_ylim(*((-1.15, 1.15) if series.cartpole else (low - 0.5, high + 0.5)))


def raster_figure(series: TrialSeries, title: str):
    """Spikes of a trial tick by tick: all of a trial of up to WINDOW_TICKS ticks; of a longer
    one its first and last WINDOW_TICKS, under an overview of all of it (the share of ticks each
    input spiked and the actions, per column of k ticks). Reward and punishment marked."""
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
    values, labels, low, high = action_axis(series, none="none")
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
        action.set_yticks(values, labels if column == 0 else [], fontsize=7)
        action.set_ylim(*((-1.3, 1.3) if series.cartpole else (low - 0.3, high + 0.3)))
        action.set_ylabel("action" if column == 0 else "", fontsize=8)
        action.set_xlabel("tick")
        action.set_xlim(ticks[0] - 0.5, right_edge(ticks))
    fig.suptitle(title)
    return fig


def draw_overview(fig, grid, series: TrialSeries, windows: list[tuple[int, int]]) -> None:
    """The raster's top rows: the share of ticks each input spiked and the actions (the
    cart-pole's mean force direction, another task's share of each action), per column of k
    ticks, with reward and punishment marked and the windows shaded."""
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
    values, labels, low, high = action_axis(series)
    if series.cartpole:
        overview_action.stairs(binned_mean(series.actions, width), columns, color=ACTION_COLOR,
                               linewidth=0.8, label="mean action", baseline=None)
        marks, top = (1.15, 1.55), 1.6
        bottom, shaded = -1.15, (0, 1)
    else:  # the share of ticks each action took, under the marks
        overview_action.pcolormesh(columns, np.arange(len(labels) + 1) - 0.5,
                                   action_shares(series, width), cmap=SHARE_MAP, vmin=0, vmax=1)
        marks, top = (high + 0.65, high + 1.05), high + 1.1
        bottom = -0.5
        shaded = ((high + 0.5 - bottom) / (top - bottom), 1)  # above the shares only
    mark_reinforcement(overview_action, series, *marks)
    for start, end in windows:
        overview_action.axvspan(series.ticks[start], series.ticks[end - 1], *shaded,
                                color="0.85", zorder=0)
    overview_action.set_yticks(values, labels, fontsize=7)
    overview_action.set_ylim(bottom, top)
    overview_action.set_ylabel("action", fontsize=8)
    overview_action.set_xlim(columns[0], right_edge(series.ticks))
    if overview_action.get_legend_handles_labels()[0]:
        overview_action.legend(fontsize=7, loc="lower left", ncol=3)
