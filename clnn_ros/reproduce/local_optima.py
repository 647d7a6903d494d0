"""Local optima, the paper's future work: exploration in the network WTA (Params.explore) against
the deterministic baseline, on many seeds; stuck seeds and means."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..batch import run_batch
from .calibration import Calibration
from .common import STUCK_BELOW, TRIALS, SeedMeans, md_table, progress, stuck, write_csv
from .learning import encodings

# ------------------------------------------------------------------------------------------------
# Settings
# ------------------------------------------------------------------------------------------------
LOCAL_OPTIMA_SEEDS = "0-127"
EXPLORE = (0.0, 0.0005, 0.001, 0.002, 0.003)  # 0: the paper's deterministic network
SHOWN = 0.001  # the exploration rate the figure compares with the baseline
LATE_TRIALS = 64  # "late": the episode's last trials, where exploration's own cost shows


@dataclass
class ExploreRun(SeedMeans):
    label: str  # encoding, e.g. "1 SV"
    explore: float
    steps: np.ndarray  # (seeds, trials)

    @property
    def late_means(self) -> np.ndarray:
        return self.steps[:, -LATE_TRIALS:].mean(axis=1)


def local_optima(seeds, cal: Calibration) -> list[ExploreRun]:
    jobs = [(label, p, e) for label, p in encodings(cal) for e in EXPLORE]
    return [ExploreRun(label, e, run_batch(seeds, p.replace(explore=e)).steps)
            for label, p, e in progress(jobs, "local optima")]


def write_local_optima(runs: list[ExploreRun], out: Path) -> Path:
    return write_csv(out / "local_optima.csv",
                     ["encoding", "explore", "seeds", "mean_steps", f"seeds_below_{STUCK_BELOW}",
                      f"mean_steps_last_{LATE_TRIALS}_trials",
                      f"seeds_below_{STUCK_BELOW}_last_{LATE_TRIALS}_trials"],
                     [[r.label, r.explore, len(r.steps), round(float(r.seed_means.mean()), 2),
                       stuck(r.seed_means), round(float(r.late_means.mean()), 2),
                       stuck(r.late_means)] for r in runs])


def plot_local_optima(runs: list[ExploreRun], path: Path) -> Path:
    from ..figures import plot_sorted_means
    panels = []
    for label in dict.fromkeys(r.label for r in runs):
        chosen = {r.explore: r for r in runs if r.label == label}
        panels.append((label, {"deterministic (the paper)": chosen[0.0].seed_means,
                               f"explore = {SHOWN:g}": chosen[SHOWN].seed_means}))
    return plot_sorted_means(panels, path, "Local optima: per-seed means, sorted, with and "
                             "without exploration", STUCK_BELOW)


def local_optima_markdown(runs: list[ExploreRun], figure: str) -> str:
    md = ["## Local optima: a way out\n"]
    md.append(
        "A three-factor rule learns only about the actions it takes, and the paper's network is "
        "deterministic: a seed whose central angle interval has locked onto the wrong action "
        "never tries the other one, and reward cancels punishment (trials just longer than "
        "sigma). Exploration noise is what lets such rules find better actions (Frémaux and "
        "Gerstner 2016, *Neuromodulated spike-timing-dependent plasticity, and theory of "
        "three-factor learning rules*). The option `explore` overrules the network WTA's "
        "winner with that probability on each tick: the other neuron acts, and its winning "
        "segment is the path that is tagged, rewarded or punished. "
        f"{len(runs[0].steps)} seeds × {TRIALS} trials; \"late\": the last {LATE_TRIALS} "
        f"trials.\n")
    md.append(md_table(["encoding", "explore", "mean steps", f"seeds below {STUCK_BELOW:,}",
                        "late mean", f"late seeds below {STUCK_BELOW:,}"],
                       [[r.label, f"{r.explore:g}", f"{r.seed_means.mean():,.0f}",
                         stuck(r.seed_means), f"{r.late_means.mean():,.0f}", stuck(r.late_means)]
                        for r in runs]) + "\n")
    md.append(local_optima_verdict(runs) + "\n")
    md.append(f"![local optima]({figure})\n")
    return "\n".join(md)


def local_optima_verdict(runs: list[ExploreRun]) -> str:
    lines = []
    for label in dict.fromkeys(r.label for r in runs):
        chosen = {r.explore: r for r in runs if r.label == label}
        base, shown = chosen[0.0], chosen[SHOWN]
        best = min(chosen.values(), key=lambda r: (stuck(r.seed_means), -r.seed_means.mean()))
        lines.append(
            f"{label}: explore = {SHOWN:g} leaves {stuck(shown.seed_means)} seeds stuck "
            f"(deterministic: {stuck(base.seed_means)}), mean {shown.seed_means.mean():,.0f} "
            f"(deterministic: {base.seed_means.mean():,.0f}); fewest stuck at explore = "
            f"{best.explore:g} ({stuck(best.seed_means)}).")
    return " ".join(lines)

