"""One trial as a bag holds it (TrialSeries), and what the pictures of a trial share: the columns
of a long trial, the marks of reward and punishment, and the action's axis (the cart-pole's
force direction, or another task's actions by their labels). No matplotlib here: the pictures
load it (clnn_ros.analysis.figures)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.task import CARTPOLE_TASK, Variable

WINDOW_TICKS = 200     # a raster window: at this width every tick stays a visible column
OVERVIEW_BINS = 400    # a whole trial in at most this many columns (a 10,000-tick one too)
# Ticks per overview column at least: several swings of a balanced pole (about 10 ticks each),
# so that a column's share of spikes does not alias with them.
OVERVIEW_MIN_TICKS = 25
ACTION_TICKS = 1000    # traces: up to here every action; beyond, a mean (or share) per column
NEAR_LIMIT = 0.6       # a bound is drawn when the motion reaches this share of it
# weights_history: a panel per neuron and segment up to this many segments; beyond, a panel per
# neuron: each input's mean over the segments
HISTORY_SEGMENTS = 8
REWARD_COLOR, PUNISH_COLOR, ACTION_COLOR = "tab:green", "tab:red", "tab:purple"
FORCE_LABELS = {-1: "-F", 0: "none", 1: "+F"}


@dataclass
class TrialSeries:
    """One trial as the bag holds it: one entry per tick that has a state message."""

    trial: int
    ticks: np.ndarray          # the run's tick numbers
    states: np.ndarray         # (ticks, variables): the values in the task's variable order (the
    #                            cart-pole: cart position m, cart velocity m/s, pole angle deg,
    #                            pole angular velocity deg/s)
    spikes: np.ndarray         # (inputs, ticks): 1 where the input spiked
    input_labels: list[str]
    actions: np.ndarray        # the cart-pole: force direction -1, +1, 0 on the last tick (or no
    #                            message); another task: the action's index, NaN on the last tick
    reinforcement: np.ndarray  # +1 reward, -1 punishment, 0 neither
    steps: int                 # successful steps
    end_reason: str
    # The task's variables (names, units, bounds: the limits drawn), and its action labels (None:
    # the cart-pole's force directions, -F and +F)
    variables: tuple[Variable, ...] = CARTPOLE_TASK.variables
    action_labels: tuple[str, ...] | None = None

    @property
    def cartpole(self) -> bool:
        """Drawn as the paper's cart-pole: actions as force directions (and its animation)."""
        return self.action_labels is None


def neuron_name(neuron: int, action_labels=None) -> str:
    """As the Action message numbers them: the cart-pole's neuron 0 drives -F, neuron 1 +F;
    another task's neuron k chooses its action k."""
    if action_labels is None:
        return f"neuron {neuron} ({FORCE_LABELS[1 if neuron else -1]})"
    label = action_labels[neuron]
    return f"neuron {neuron} ({f'action {label}' if label.isdigit() else label})"


def action_axis(series: TrialSeries, none: str = "0") -> tuple[list, list[str], float, float]:
    """The action axis: its ticks, their labels, the lowest and the highest action. The
    cart-pole's: -F, `none` (the last tick), +F; another task's: its actions by label."""
    if series.cartpole:
        return [-1, 0, 1], ["-F", none, "+F"], -1.0, 1.0
    count = len(series.action_labels)
    return list(range(count)), list(series.action_labels), 0.0, count - 1.0


def variable_label(variable: Variable) -> str:
    """A variable's axis label: its name in words, its unit."""
    words = variable.name.replace("_", " ")
    if len(words) > 16 and " " in words:  # two lines
        cut = words.rfind(" ", 0, len(words) // 2 + 4)
        words = words[:cut] + "\n" + words[cut + 1:] if cut > 0 else words
    return words + (f" ({variable.unit})" if variable.unit else "")


def bin_width(ticks: int) -> int:
    """Ticks per overview column: `ticks` in at most OVERVIEW_BINS columns of at least
    OVERVIEW_MIN_TICKS."""
    return max(OVERVIEW_MIN_TICKS, math.ceil(ticks / OVERVIEW_BINS))


def column_starts(count: int, width: int) -> np.ndarray:
    """The first entry of each column of `width` entries (the last column may be shorter)."""
    return np.arange(0, count, width)


def binned_mean(values: np.ndarray, width: int) -> np.ndarray:
    """The mean of each column of `width` consecutive entries along the last axis (NaN entries
    left out: a column of NaN alone is NaN)."""
    count = values.shape[-1]
    starts = column_starts(count, width)
    values = values.astype(np.float64)
    if not np.isnan(values).any():
        sizes = np.diff(np.append(starts, count))
        return np.add.reduceat(values, starts, axis=-1) / sizes
    finite = ~np.isnan(values)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.add.reduceat(np.where(finite, values, 0.0), starts, axis=-1) / \
            np.add.reduceat(finite.astype(np.float64), starts, axis=-1)


def action_shares(series: TrialSeries, width: int) -> np.ndarray:
    """(actions, columns): the share of each column's ticks on which each action was chosen
    (another task's, whose actions need not be ordered: no mean of them)."""
    chosen = np.array([series.actions == k for k in range(len(series.action_labels))])
    return binned_mean(chosen, width)


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
