"""Plotting for the reproduction of Smith (2024), Figures 7-15 (matplotlib, Agg backend).

Plotting only: every function takes arrays that clnn_ros.reproduce computed and writes one PNG.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402

DPI = 110
END_COLORS = {0: "tab:green", 1: "tab:red", 2: "tab:blue"}  # reached the cap, pole angle, cart position
END_LABELS = {0: "reached the step cap", 1: "failed: pole angle", 2: "failed: cart position"}
LINE_STYLES = ("--", ":", "-.", (0, (5, 1, 1, 1)))
LINE_COLORS = ("black", "tab:purple", "tab:orange", "tab:brown")
HEADROOM = 1.32  # y axis up to 1.32 x the step cap: room for the legend above the bars
NEAR_LIMIT = 0.5  # a trace whose motion reaches this fraction of a failure limit shows the limit
MOTION_MARGIN = 1.1  # a trace's y axis: up to 1.1 x its largest excursion (or limit)


def _save(fig, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return path


def _reference_lines(ax, lines: dict[str, float]) -> None:
    for k, (label, value) in enumerate(lines.items()):
        ax.axhline(value, color=LINE_COLORS[k % len(LINE_COLORS)],
                   linestyle=LINE_STYLES[k % len(LINE_STYLES)], linewidth=1.4,
                   label=f"{label}: {value:,.0f}")


def _legend_on_top(ax) -> None:
    """The legend in the empty band above the step cap (the y axis leaves HEADROOM for it)."""
    ax.legend(fontsize=8, loc="upper center", ncol=3, framealpha=0.9)


def input_labels(nsv: int) -> list[str]:
    """The paper's input numbering: angle intervals 1-6, then velocity intervals 1-3."""
    labels = [f"θ{k}" for k in range(1, 7)]
    return labels + [f"v{k}" for k in range(1, 4)] if nsv == 2 else labels


def plot_weights(weights: np.ndarray, path: Path, title: str) -> Path:
    """Figures 7 and 12: the two neurons' weight matrices (segments x inputs) as annotated heat-maps."""
    nsv = 1 if weights.shape[2] == 6 else 2
    labels = input_labels(nsv)
    q = weights.shape[1]
    fig, axes = plt.subplots(1, 2, figsize=(2.0 + 0.55 * len(labels) * 2, 1.2 + 0.38 * q),
                             constrained_layout=True)
    vmax = max(float(weights.max()), 1e-9)
    for neuron, ax in enumerate(axes):
        ax.imshow(weights[neuron], cmap="Greys", vmin=0, vmax=vmax * 1.6, aspect="auto")
        for s in range(q):
            for i in range(len(labels)):
                w = weights[neuron, s, i]
                ax.text(i, s, f"{w:g}", ha="center", va="center", fontsize=8,
                        color="white" if w > vmax * 0.8 else "black")
        ax.set_xticks(range(len(labels)), labels)
        ax.set_yticks(range(q), [str(s + 1) for s in range(q)])
        ax.set_xlabel("input (θ = angle interval, v = dx/dt interval, Table 1)")
        ax.set_ylabel("segment")
        ax.set_title("-F neuron" if neuron == 0 else "+F neuron")
    fig.suptitle(title)
    return _save(fig, path)


def plot_steps_per_angle(panels: list[tuple], path: Path, title: str, max_steps: int) -> Path:
    """Figures 8 and 13: successful steps per initial angle (bars coloured by how the trial ended).
    `panels` is a list of (subtitle, angles, steps, end_status, reference lines {label: value})."""
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 3.3 * len(panels)), squeeze=False,
                             constrained_layout=True)
    for ax, (subtitle, angles, steps, status, lines) in zip(axes[:, 0], panels):
        width = 0.8 * (angles[1] - angles[0]) if len(angles) > 1 else 0.05
        for code, label in END_LABELS.items():
            mask = status == code
            if mask.any():
                ax.bar(angles[mask], steps[mask], width=width, color=END_COLORS[code], label=label)
        _reference_lines(ax, {"mean (measured)": float(np.mean(steps)), **lines})
        ax.set_ylim(0, max_steps * HEADROOM)
        ax.set_xlabel("initial angle (deg)")
        ax.set_ylabel("successful steps")
        ax.set_title(subtitle, fontsize=10)
        _legend_on_top(ax)
    fig.suptitle(title)
    return _save(fig, path)


def plot_seed_means(seeds: np.ndarray, means: np.ndarray, path: Path, title: str,
                    lines: dict[str, float], sort: bool = False, max_steps: int = 10_000) -> Path:
    """Figures 9 and 14: mean successful steps per seed (episode), optionally sorted high to low."""
    order = np.argsort(-means, kind="stable") if sort else np.arange(len(means))
    fig, ax = plt.subplots(figsize=(10, 4), constrained_layout=True)
    x = np.arange(len(means))
    ax.bar(x, means[order], color="tab:gray", label="learned (mean over the episode's trials)")
    _reference_lines(ax, lines)
    ax.set_xticks(x, [str(s) for s in seeds[order]], fontsize=7, rotation=90 if len(x) > 40 else 0)
    ax.set_xlabel("seed" + (" (sorted by mean, high to low)" if sort else ""))
    ax.set_ylabel("mean successful steps")
    ax.set_ylim(0, max_steps * HEADROOM)
    ax.set_title(title)
    _legend_on_top(ax)
    return _save(fig, path)


def plot_learning_curves(steps: np.ndarray, path: Path, title: str, lines: dict[str, float],
                         max_steps: int = 10_000) -> Path:
    """Successful steps per trial: each seed faint, the mean over seeds bold."""
    fig, ax = plt.subplots(figsize=(10, 4), constrained_layout=True)
    trials = np.arange(1, steps.shape[1] + 1)
    for row in steps:
        ax.plot(trials, row, color="tab:gray", alpha=0.07, linewidth=0.4, rasterized=True)
    ax.plot(trials, steps.mean(axis=0), color="tab:blue", linewidth=1.8,
            label=f"mean over {steps.shape[0]} seeds")
    _reference_lines(ax, lines)
    ax.set_xlabel("trial")
    ax.set_ylabel("successful steps")
    ax.set_xlim(1, steps.shape[1])
    ax.set_ylim(0, max_steps * HEADROOM)
    ax.set_title(title)
    _legend_on_top(ax)
    return _save(fig, path)


def plot_trace(trace: np.ndarray, first_step: int, path: Path, title: str,
               angle_limit: float, track_limit: float) -> Path:
    """Figures 10, 11, 15: pole angle and cart position against the step, each axis scaled to
    the motion (a balanced pole's +-0.3 deg is flat on a +-12 deg axis); the failure limits are
    drawn where the motion comes near them.
    `trace` rows are states (x, x_dot, theta_deg, theta_dot_deg); row k is after step first_step + k."""
    step = first_step + np.arange(len(trace))
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 5), sharex=True, constrained_layout=True)
    for ax, values, limit, unit, color, label in (
            (top, trace[:, 2], angle_limit, "deg", "tab:red", "pole angle (deg)"),
            (bottom, trace[:, 0], track_limit, "m", "tab:blue", "cart position (m)")):
        ax.plot(step, values, color=color, linewidth=0.8)
        ax.set_ylabel(label)
        _scale_to_motion(ax, values, limit, unit)
    bottom.set_xlabel("step")
    bottom.set_xlim(step[0], step[-1])
    fig.suptitle(title)
    return _save(fig, path)


def _scale_to_motion(ax, values: np.ndarray, limit: float, unit: str) -> None:
    """Symmetric y limits around the motion; the failure limits drawn if it reaches half of them,
    else named in a corner."""
    peak = float(np.abs(values).max()) if len(values) else 0.0
    if peak >= NEAR_LIMIT * limit:
        for sign in (1, -1):
            ax.axhline(sign * limit, color="gray", linestyle="--", linewidth=0.8,
                       label="failure limits" if sign > 0 else None)
        ax.set_ylim(-limit * MOTION_MARGIN, limit * MOTION_MARGIN)
        ax.legend(fontsize=8, loc="upper right")
    else:
        ax.set_ylim(-max(peak, 1e-6) * MOTION_MARGIN, max(peak, 1e-6) * MOTION_MARGIN)
        ax.text(0.995, 0.97, f"failure limits +-{limit:g} {unit}, off this scale",
                transform=ax.transAxes, ha="right", va="top", fontsize=8, color="gray")


def plot_edge_scan(edges: np.ndarray, means: dict[str, np.ndarray], path: Path, title: str,
                   marks: dict[str, float], max_steps: int = 10_000) -> Path:
    """Mean steps of the Figure 12 weights against the velocity edge, one line per physics mode."""
    fig, ax = plt.subplots(figsize=(9, 4), constrained_layout=True)
    for label, values in means.items():
        ax.plot(edges, values, marker="o", markersize=3, label=label)
    for k, (label, edge) in enumerate(marks.items()):
        ax.axvline(edge, color=LINE_COLORS[k % len(LINE_COLORS)],
                   linestyle=LINE_STYLES[k % len(LINE_STYLES)], linewidth=1, label=f"{label}: {edge:g}")
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
    ax.set_xlabel("velocity edge e (m/s): intervals (-inf,-e) [-e,e) [e,inf)")
    ax.set_ylabel("mean successful steps, 32 angles")
    ax.set_ylim(0, max_steps * HEADROOM)
    ax.set_title(title)
    _legend_on_top(ax)
    return _save(fig, path)


def plot_config_means(labels: list[str], means: np.ndarray, stuck: list[int], path: Path,
                      title: str, xlabel: str, max_steps: int = 10_000) -> Path:
    """A sweep: mean steps over the seeds per configuration, with the stuck seeds written on."""
    fig, ax = plt.subplots(figsize=(max(6, 0.6 * len(labels) + 2), 4), constrained_layout=True)
    x = np.arange(len(labels))
    bars = ax.bar(x, means, color="tab:blue")
    for bar, count in zip(bars, stuck):
        ax.annotate(f"{count} stuck", (bar.get_x() + bar.get_width() / 2, bar.get_height()),
                    ha="center", va="bottom", fontsize=7)
    ax.set_xticks(x, labels, fontsize=8, rotation=30 if len(labels) > 6 else 0, ha="right"
                  if len(labels) > 6 else "center")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("mean successful steps")
    ax.set_ylim(0, max_steps * HEADROOM)
    ax.set_title(title)
    return _save(fig, path)


def plot_heatmap(table: np.ndarray, rows: list, cols: list, names: list[str], path: Path,
                 title: str, max_steps: int = 10_000) -> Path:
    """A two-parameter sweep: mean steps over the seeds, one cell per configuration."""
    fig, ax = plt.subplots(figsize=(max(5, 0.9 * len(cols) + 3), max(3, 0.6 * len(rows) + 2)),
                           constrained_layout=True)
    image = ax.imshow(table, cmap="viridis", vmin=0, vmax=max_steps, aspect="auto")
    for (r, c), value in np.ndenumerate(table):
        ax.text(c, r, f"{value:,.0f}", ha="center", va="center", fontsize=8,
                color="white" if value < max_steps / 2 else "black")
    ax.set_xticks(range(len(cols)), [f"{v:g}" if isinstance(v, float) else v for v in cols])
    ax.set_yticks(range(len(rows)), [f"{v:g}" if isinstance(v, float) else v for v in rows])
    ax.set_xlabel(names[1])
    ax.set_ylabel(names[0])
    fig.colorbar(image, ax=ax, label="mean successful steps")
    ax.set_title(title)
    return _save(fig, path)


def plot_sorted_means(panels: list[tuple[str, dict[str, np.ndarray]]], path: Path, title: str,
                      stuck_below: float, max_steps: int = 10_000) -> Path:
    """Per-seed means sorted high to low, one line per variant, one panel per encoding."""
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4), sharey=True,
                             constrained_layout=True, squeeze=False)
    for ax, (label, variants) in zip(axes[0], panels):
        for k, (name, means) in enumerate(variants.items()):
            ax.plot(np.sort(means)[::-1], color=LINE_COLORS[k % len(LINE_COLORS)],
                    linestyle="-" if k == 0 else LINE_STYLES[k % len(LINE_STYLES)], label=name)
        ax.axhline(stuck_below, color="tab:red", linewidth=0.8, linestyle=":",
                   label=f"stuck below {stuck_below:,.0f}")
        ax.set_title(label)
        ax.set_xlabel("seeds, sorted by mean (high to low)")
        ax.set_ylim(0, max_steps * HEADROOM)
        ax.legend(fontsize=8, loc="upper right")
    axes[0][0].set_ylabel("mean successful steps")
    fig.suptitle(title)
    return _save(fig, path)


def plot_task_returns(curves: dict[str, np.ndarray], path: Path, title: str,
                      threshold: float | None) -> Path:
    """Learning curves of a task: for each label's returns (seeds x episodes), per episode the
    median and quartiles over seeds of each seed's mean of its last 10 returns; the task's
    threshold."""
    fig, ax = plt.subplots(figsize=(8, 4.5), constrained_layout=True)
    for label, returns in curves.items():
        smooth = np.array([np.convolve(r, np.ones(10))[:len(r)] /
                           np.minimum(np.arange(len(r)) + 1, 10) for r in returns])
        q1, q2, q3 = np.percentile(smooth, (25, 50, 75), axis=0)
        episodes = np.arange(1, returns.shape[1] + 1)
        line, = ax.plot(episodes, q2, label=label)
        ax.fill_between(episodes, q1, q3, color=line.get_color(), alpha=0.2)
    if threshold is not None:
        ax.axhline(threshold, color="grey", linestyle=":", label=f"threshold {threshold:g}")
    ax.set_xlabel("episode")
    ax.set_ylabel("return (mean of the last 10 episodes)")
    ax.set_title(f"{title}: median and quartiles over seeds")
    ax.legend(fontsize=7)
    return _save(fig, path)
