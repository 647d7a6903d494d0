"""The cart-pole's animation of a trial (`python -m clnn_ros.analysis BAG --animate N`): the cart
and the pole to scale, each tick's spikes and action beside them, as a GIF. The paper's
cart-pole's alone: another task's trial has its traces (clnn_ros.analysis.trial_figures)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from ..figures import plt
from .series import ACTION_COLOR, PUNISH_COLOR, TrialSeries

GIF_FRAMES = 300       # longer trials are shown every k-th tick
GIF_FPS = 20
GIF_DPI = 80


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

