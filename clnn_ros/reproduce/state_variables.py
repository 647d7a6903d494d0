"""More state variables, the paper's way forward: the cart position and the pole's angular
velocity encoded beside the angle (and the cart velocity), learned with the batch engine."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..batch import run_batch
from ..core.params import Params
from .calibration import Calibration
from .common import (MAX_STEPS, STUCK_BELOW, TRIALS, SeedMeans, md_table, progress, stuck,
                     write_csv)

# ------------------------------------------------------------------------------------------------
# Settings
# ------------------------------------------------------------------------------------------------
STATE_VAR_SEEDS = "0-31"
LATE_TRIALS = 64  # the episode's last trials: what it has learned
# (state variables, segments: None = half the input combinations); the velocity edge is the
# calibration scan's best. The segment-count rows test whether the count explains the result.
ENCODINGS = (
    ("pole_angle", None),
    ("pole_angle,cart_position", None),
    ("pole_angle,pole_angular_velocity", None),
    ("pole_angle,cart_velocity,cart_position", None),
    ("pole_angle,cart_velocity,cart_position", 9),
    ("pole_angle,cart_velocity,cart_position,pole_angular_velocity", None),
    ("pole_angle,cart_velocity,cart_position,pole_angular_velocity", 9),
)


@dataclass
class EncodingRun(SeedMeans):
    params: Params
    steps: np.ndarray  # (seeds, trials)

    @property
    def late_capped(self) -> float:
        """The share of the last LATE_TRIALS trials that reached the cap."""
        return float((self.steps[:, -LATE_TRIALS:] >= MAX_STEPS).mean())


def state_variable_runs(seeds, cal: Calibration) -> list[EncodingRun]:
    runs = []
    for names, segments in progress(ENCODINGS, "state variables"):
        p = Params(state_vars=names, segments=segments, trials=TRIALS,
                   velocity_edge=cal.best_edge)
        runs.append(EncodingRun(p, run_batch(seeds, p).steps))
    return runs


def write_state_variables(runs: list[EncodingRun], out: Path) -> Path:
    return write_csv(out / "state_variables.csv",
                     ["state_vars", "inputs", "segments", "seeds", "mean_steps",
                      f"seeds_below_{STUCK_BELOW}", f"capped_share_last_{LATE_TRIALS}_trials"],
                     [[",".join(r.params.state_vars), r.params.n_inputs, r.params.n_segments,
                       len(r.steps), round(float(r.seed_means.mean()), 2), stuck(r.seed_means),
                       round(r.late_capped, 4)] for r in runs])


def state_variables_markdown(runs: list[EncodingRun], best_edge: float) -> str:
    p = Params()
    md = ["## More state variables\n"]
    md.append(
        f"Any of the four state variables, in any order (`--state-vars`); edges: Table 1's for "
        f"the angle, the scan's best {best_edge:g} m/s for the cart velocity, "
        f"{', '.join(f'{e:g}' for e in p.position_edges_m)} m for the cart position (thirds of "
        f"the track) and {', '.join(f'{e:g}' for e in p.angular_velocity_edges_deg_per_s)} "
        f"deg/s for the pole's angular velocity (the median |theta_dot| of the Figure 7 "
        f"weights' trials). Segments: half the input combinations unless given. "
        f"{len(runs[0].steps)} seeds × {TRIALS} trials.\n")
    md.append(md_table(["state variables", "inputs", "segments", "mean steps",
                        f"seeds below {STUCK_BELOW:,}", f"last {LATE_TRIALS} trials at the cap"],
                       [[", ".join(r.params.state_vars), r.params.n_inputs, r.params.n_segments,
                         f"{r.seed_means.mean():,.0f}", stuck(r.seed_means),
                         f"{r.late_capped:.0%}"] for r in runs]) + "\n")
    md.append(state_variables_verdict(runs) + "\n")
    return "\n".join(md)


def state_variables_verdict(runs: list[EncodingRun]) -> str:
    """What learns (as well as the angle alone, by the mean), and whether the segment count
    explains the rest."""
    reference = runs[0].seed_means.mean()
    by_vars: dict[tuple, list[EncodingRun]] = {}
    for r in runs:
        by_vars.setdefault(r.params.state_vars, []).append(r)
    keeps = [", ".join(v) for v, rs in by_vars.items() if len(v) > 1
             and max(r.seed_means.mean() for r in rs) >= 0.8 * reference]
    segment_rows = [rs for rs in by_vars.values() if len(rs) > 1]
    spread = max((max(r.seed_means.mean() for r in rs) / min(r.seed_means.mean() for r in rs)
                  for rs in segment_rows), default=1.0)
    return (f"Within 80 % of the angle alone ({reference:,.0f}): "
            f"{'; '.join(keeps) or 'no other encoding'}. The segment count does "
            + ("not explain the others: with fewer segments they learn about as well or badly "
               f"(the largest ratio of means between segment counts is {spread:.2f})."
               if spread < 1.25 else f"matter (means differ by {spread:.2f}x between segment "
                                    f"counts)."))
