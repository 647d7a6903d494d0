"""Learning: the paper's runs with the batch engine (1 SV; 2 SV at Table 1's literal velocity edge
and at the calibration scan's best edge), their per-trial CSVs and final weights."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..batch import BatchResult
from ..core.params import Params
from ..core.episode import returns
from ..core.physics import CONTINUE
from ..core.solving import SOLVED_MEAN, WINDOW, solving_summary
from .calibration import Calibration
from .common import (LITERAL_EDGE, STUCK_BELOW, TRIALS, end_reason, progress, stuck, units_batch,
                     write_csv)


@dataclass
class Run:
    name: str  # file tag, e.g. "1sv" or "2sv_edge0.3406"
    label: str  # for titles and tables
    params: Params
    result: BatchResult

    @property
    def seed_means(self) -> np.ndarray:
        return self.result.steps.mean(axis=1)


@dataclass
class PaperRuns:
    """The paper's three encodings, learned on the same seeds."""
    one_sv: Run
    two_sv_literal: Run  # Table 1's velocity edge
    two_sv_best: Run  # the calibration scan's best edge

    def all(self) -> tuple[Run, Run, Run]:
        """In the order every table lists them: 1 SV, 2 SV literal edge, 2 SV best edge."""
        return self.one_sv, self.two_sv_literal, self.two_sv_best


def learn_run(name: str, label: str, seeds, p: Params, store: Path | None = None,
              log=None) -> Run:
    """The batch engine's episodes of p on seeds, run as units on the current executor (and kept
    in `store`, a unit at a time, when given: see run_units)."""
    return Run(name, label, p, units_batch(p, seeds, "learn", store, log=log))


def write_learn_outputs(run: Run, out: Path) -> list[Path]:
    """learn_<name>.csv (one row per trial), final_weights_<name>.npz and .csv."""
    r = run.result
    trial_rows = ([int(seed), trial, repr(float(r.initial_angles[k, trial])),
                   int(r.steps[k, trial]), end_reason(r.end_status[k, trial])]
                  for k, seed in enumerate(r.seeds) for trial in range(r.steps.shape[1]))
    weight_rows = ([int(seed), n, s, i, repr(float(r.final_weights[k, n, s, i]))]
                   for k, seed in enumerate(r.seeds) for n in range(2)
                   for s in range(r.final_weights.shape[2]) for i in range(r.final_weights.shape[3]))
    out.mkdir(parents=True, exist_ok=True)
    npz = out / f"final_weights_{run.name}.npz"
    np.savez_compressed(npz, seeds=r.seeds, final_weights=r.final_weights, steps=r.steps,
                        end_status=r.end_status, initial_angles=r.initial_angles,
                        params=json.dumps(run.params.to_dict()))
    return [write_csv(out / f"learn_{run.name}.csv",
                      ["seed", "trial", "initial_angle_deg", "steps", "end_reason"], trial_rows),
            npz,
            write_csv(out / f"final_weights_{run.name}.csv",
                      ["seed", "neuron", "segment", "input", "weight"], weight_rows)]


def print_seed_means(run: Run) -> None:
    r, means = run.result, run.seed_means
    print(f"{run.label}: {len(r.seeds)} seeds x {r.steps.shape[1]} trials "
          f"({r.wall_s:.1f} s in the batch engine)")
    print(f"{'seed':>6s} {'mean steps':>11s} {'trials at cap':>14s}")
    for seed, mean, capped in zip(r.seeds, means, (r.end_status == CONTINUE).sum(axis=1)):
        print(f"{seed:6d} {mean:11.1f} {capped:14d}")
    if run.params.protocol == "gymnasium":  # judged as the field judges CartPole-v1
        print(f"overall mean {means.mean():.1f}")
        print(solving_line(solving_summary(returns(r.steps, r.end_status))))
    else:
        print(f"overall mean {means.mean():.1f}; seeds stuck below {STUCK_BELOW}: "
              f"{stuck(means)}")


def solving_line(summary: dict) -> str:
    """How many seeds solved CartPole-v1 and what it took them, in one line."""
    line = (f"solved CartPole-v1 (last {WINDOW} returns averaging {SOLVED_MEAN:g} or more): "
            f"{summary['solved']} of {summary['seeds']} seeds")
    if summary["solved"]:
        (e1, e2, e3), (s1, s2, s3) = summary["episodes"], summary["steps"]
        line += (f"; episodes to solve: median {e2:g} (quartiles {e1:g}-{e3:g}); environment "
                 f"steps: median {s2:,.0f} (quartiles {s1:,.0f}-{s3:,.0f})")
    return line


def encodings(cal: Calibration) -> list[tuple[str, Params]]:
    """(label, params) of the two encodings the studies beyond the paper use: 1 SV, and 2 SV at
    the calibration scan's best edge."""
    return [("1 SV", Params(nsv=1, trials=TRIALS)),
            (f"2 SV, edge {cal.best_edge:g}", Params(nsv=2, trials=TRIALS,
                                                     velocity_edge=cal.best_edge))]


def paper_runs(seeds, cal: Calibration) -> PaperRuns:
    """The paper's runs: 1 SV, 2 SV at the literal edge, 2 SV at the scan's best edge."""
    edge = cal.best_edge
    jobs = [("1sv", "1 SV", Params(nsv=1, trials=TRIALS)),
            ("2sv", f"2 SV, literal edge {LITERAL_EDGE:g}", Params(nsv=2, trials=TRIALS)),
            (f"2sv_edge{edge:g}", f"2 SV, scan's best edge {edge:g}",
             Params(nsv=2, trials=TRIALS, velocity_edge=edge))]
    return PaperRuns(*(learn_run(name, label, seeds, p)
                       for name, label, p in progress(jobs, "learn")))
