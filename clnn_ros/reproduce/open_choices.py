"""Open choices, one at a time: each option the paper leaves open switched alone from the paper
defaults, learned with 1 SV, 2 SV at the literal edge and 2 SV at the scan's best edge; and 2 SV
against the velocity edge."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..batch import evaluate_weights_batch, run_batch
from ..core.optimal import optimal_weights
from ..core.params import Params
from .calibration import Calibration
from .common import LITERAL_EDGE, STUCK_BELOW, TRIALS, md_table, progress, stuck, write_csv

# ------------------------------------------------------------------------------------------------
# Settings
# ------------------------------------------------------------------------------------------------
OPTION_SEEDS = "0-127"  # four times the paper's 32: the batch engine makes them cheap
OPTIONS = (  # each switched alone from the paper defaults
    ("tie_break", "index"), ("tie_break", "random"), ("inference", "exact"),
    ("tagging", "both_neurons"), ("e_flag", "live"), ("punish_timing", "after_decay"),
    ("decay_counters", "carry"), ("success_counter", "carry"), ("first_action", "no_force"),
    ("integrator", "euler"), ("physics", "correct"), ("physics", "integration_slip"),
    ("angle_span_deg", 0.75), ("angle_span_deg", 3.0),  # the start-angle grid of learning
    ("n_angles", 8),
    ("w_range", 1.0),  # initial weights spread over a whole integer: no ties at the start
    ("w_base", 2.5),
    ("explore", 0.001))  # the way out of local optima (local_optima.py)
EDGES = (0.1, 0.25, 0.5, 1.0, 2.0, 5.0)  # 2-SV learning at these edges (+ the scan's best)
DEFAULTS = "(paper defaults)"  # the option column of the unchanged runs
VELOCITY_EDGE = "velocity_edge"  # the option column of the edge rows


@dataclass
class OptionRun:
    option: str  # a Params field, DEFAULTS or VELOCITY_EDGE
    value: str  # "" for the defaults
    nsv: int
    velocity_edge: float
    seeds: np.ndarray
    means: np.ndarray  # per-seed mean steps
    fig12_mean: float | None = None  # edge rows: the Figure 12 weights at that edge


def open_choices(seeds, cal: Calibration) -> list[OptionRun]:
    """Each open choice switched alone from the paper defaults; 1 SV, 2 SV literal and best edge;
    then 2 SV at each of EDGES and the best edge."""
    edge = cal.best_edge
    configs = [(DEFAULTS, "", {})] + [(k, f"{v:g}" if isinstance(v, float) else str(v), {k: v})
                                      for k, v in OPTIONS]
    jobs = [(name, value, nsv, e, change)
            for name, value, change in configs
            for nsv, e in ((1, LITERAL_EDGE), (2, LITERAL_EDGE), (2, edge))]
    jobs += [(VELOCITY_EDGE, f"{e:g}", 2, e, {}) for e in sorted(set(EDGES) | {edge})]
    rows, done = [], {}
    for name, value, nsv, e, change in progress(jobs, "ambiguity"):
        p = Params(nsv=nsv, velocity_edge=e, trials=TRIALS, **change)
        if p not in done:  # the edge rows at 5 and the best edge repeat the defaults' runs
            done[p] = run_batch(seeds, p).steps.mean(axis=1)
        fig12_mean = (float(evaluate_weights_batch(optimal_weights(2), p).steps.mean())
                      if name == VELOCITY_EDGE else None)
        rows.append(OptionRun(name, value, nsv, e, np.asarray(seeds), done[p], fig12_mean))
    return rows


def write_open_choices(rows: list[OptionRun], out: Path) -> list[Path]:
    summary = [[r.option, r.value, r.nsv, r.velocity_edge, len(r.seeds),
                round(float(r.means.mean()), 2), stuck(r.means)] for r in rows]
    per_seed = [[r.option, r.value, r.nsv, r.velocity_edge, int(s), round(float(m), 3)]
                for r in rows for s, m in zip(r.seeds, r.means)]
    return [write_csv(out / "ambiguity.csv", ["option", "value", "nsv", "velocity_edge", "seeds",
                                              "mean_steps", f"seeds_below_{STUCK_BELOW}"], summary),
            write_csv(out / "ambiguity_per_seed.csv",
                      ["option", "value", "nsv", "velocity_edge", "seed", "mean_steps"], per_seed)]


def open_choices_markdown(rows: list[OptionRun], best_edge: float, n_seeds: int) -> str:
    md = ["## Open choices, one at a time\n"]
    md.append(f"Each row switches one option from the paper defaults; {n_seeds} seeds "
              f"× {TRIALS} trials; cells are the mean over seeds of the per-seed mean steps, with "
              f"the number of seeds below {STUCK_BELOW:,} in brackets.\n")
    table = {}
    for r in rows:
        if r.option == VELOCITY_EDGE:
            continue
        col = 0 if r.nsv == 1 else (1 if r.velocity_edge == LITERAL_EDGE else 2)
        table.setdefault((r.option, r.value), ["", "", ""])[col] = \
            f"{r.means.mean():,.0f} ({stuck(r.means)})"
    md.append(md_table(["option", "value", "1 SV", f"2 SV, edge {LITERAL_EDGE:g}",
                        f"2 SV, edge {best_edge:g}"],
                       [[k[0], k[1] or "—", *v] for k, v in table.items()]) + "\n")
    edge_rows = [[f"{r.velocity_edge:g}", f"{r.fig12_mean:,.0f}", f"{r.means.mean():,.0f}",
                  str(stuck(r.means))] for r in rows if r.option == VELOCITY_EDGE]
    md.append("2 SV against the velocity edge (paper defaults otherwise):\n")
    md.append(md_table(["velocity edge (m/s)", "Figure 12 weights mean", "learned mean",
                        f"seeds below {STUCK_BELOW:,}"], edge_rows) + "\n")
    return "\n".join(md)
