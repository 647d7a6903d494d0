"""Sensitivity: a grid of parameter values learned with the batch engine (`reproduce sweep`), and
the one-at-a-time table that tests the paper's claim that results are "relatively insensitive"
to the Table 2 parameters (section 3.2)."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..batch import run_batch
from ..core.episode import returns as episode_returns
from ..core.params import ParamError, Params, params_from_strings
from ..core.solving import solving_summary
from .common import (STUCK_BELOW, TRIALS, SeedMeans, md_table, progress, run_units, stuck,
                     write_csv)

# ------------------------------------------------------------------------------------------------
# Settings
# ------------------------------------------------------------------------------------------------
SENSITIVITY_SEEDS = "0-63"
FACTORS = (0.25, 0.5, 2.0, 4.0)  # each parameter at these multiples of its Table 2 value
SWEPT = ("sigma", "omega", "rho_plus", "rho_minus", "punish", "segments", "w_max")
INTEGER = ("sigma", "omega", "segments")  # rounded to the nearest integer, at least 1
# "Relatively insensitive": halving or doubling any parameter moves the mean over the seeds by
# less than this fraction of the Table 2 run's mean.
INSENSITIVE_WITHIN = 0.25


@dataclass
class SweepRun(SeedMeans):
    values: dict  # the swept parameters' values of this configuration
    params: Params
    seeds: np.ndarray
    steps: np.ndarray  # (seeds, trials)
    end_status: np.ndarray  # (seeds, trials)

    @property
    def tag(self) -> str:
        return "_".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                        for k, v in self.values.items())

    @cached_property
    def judged(self) -> list[tuple[str, str, object, object]]:
        """A configuration's summary columns, each (CSV name, table name, CSV value, table
        value): the mean over the seeds of the per-seed mean steps, and under the paper's
        protocol the seeds below STUCK_BELOW; under gymnasium's (episodes of 500 steps at most)
        the seeds that solved CartPole-v1 and the median episodes it took them (core.solving).
        Computed once: the CSV and the table both take it."""
        mean = float(self.seed_means.mean())
        if self.params.protocol != "gymnasium":
            below = stuck(self.seed_means)
            return [("mean_steps", "mean steps", round(mean, 2), f"{mean:,.0f}"),
                    (f"seeds_below_{STUCK_BELOW}", f"seeds below {STUCK_BELOW:,}", below, below)]
        solving = solving_summary([episode_returns(steps, status)
                                   for steps, status in zip(self.steps, self.end_status)])
        median = solving["episodes"][1] if solving["episodes"] else None
        return [("mean_steps", "mean steps", round(mean, 2), f"{mean:,.1f}"),
                ("seeds_solved", "seeds solved", solving["solved"],
                 f"{solving['solved']} of {len(self.seeds)}"),
                ("median_episodes_to_solve", "median episodes to solve",
                 "" if median is None else median, "—" if median is None else f"{median:g}")]


def parse_grid(items: list[str]) -> dict[str, list[str]]:
    """--param NAME=V1,V2,... items -> {NAME: [V1, V2, ...]}; ValueError with one line."""
    grid = {}
    for item in items:
        name, sep, values = item.partition("=")
        name = name.strip()
        listed = [v.strip() for v in values.split(",") if v.strip()]
        if not sep or not name or not listed:
            raise ValueError(f"--param expects NAME=V1,V2,..., got {item!r}")
        if name in grid:
            raise ValueError(f"--param {name} is given twice")
        grid[name] = listed
    if not grid:
        raise ValueError("give at least one --param NAME=V1,V2,...")
    return grid


def sweep_configs(base: Params, grid: dict[str, list]) -> list[tuple[dict, Params]]:
    """Every combination of the grid's values (text or numbers) on top of `base`: (the swept
    values, the parameters) each, all validated (ParamError)."""
    names = list(grid)
    configs = []
    for combination in itertools.product(*(grid[n] for n in names)):
        given = dict(zip(names, combination))
        p = params_from_strings({k: str(v) for k, v in given.items()}, base)
        configs.append(({n: getattr(p, n) for n in names}, p))
    return configs


def sweep(configs: list[tuple[dict, Params]], seeds, store: Path, log=None) -> list[SweepRun]:
    """The configurations (sweep_configs) learned on `seeds`: their units (a configuration x a
    block of seeds) run on the current executor; a finished unit is stored in `store` and not
    run again (an interrupted sweep resumes). log: see run_units."""
    results = run_units([(p, seeds) for _, p in configs], "sweep", store, log=log,
                        keep=("steps", "end_status"))
    return [SweepRun(values, p, np.asarray(seeds), result["steps"], result["end_status"])
            for (values, p), result in zip(configs, results)]


def write_sweep(runs: list[SweepRun], out: Path) -> list[Path]:
    """sweep_<config>.csv (one row per trial) for each configuration and sweep_summary.csv."""
    files = []
    for run in runs:
        files.append(write_csv(out / f"sweep_{run.tag}.csv",
                               ["seed", "trial", "steps"],
                               ([int(seed), trial, int(run.steps[k, trial])]
                                for k, seed in enumerate(run.seeds)
                                for trial in range(run.steps.shape[1]))))
    names = list(runs[0].values)
    files.append(write_csv(out / "sweep_summary.csv",
                           [*names, "seeds", "trials", *(c[0] for c in runs[0].judged)],
                           [[*run.values.values(), len(run.seeds), run.steps.shape[1],
                             *(c[2] for c in run.judged)] for run in runs]))
    return files


def plot_sweep(runs: list[SweepRun], path: Path, title: str) -> Path:
    """One swept parameter: mean steps (and stuck seeds) against its values; two: a heat-map of
    the mean; more: one bar per configuration."""
    from .. import figures as plots
    names = list(runs[0].values)
    means = np.array([run.seed_means.mean() for run in runs])
    labels = [run.tag for run in runs]
    if len(names) == 2:
        rows = sorted({run.values[names[0]] for run in runs})
        cols = sorted({run.values[names[1]] for run in runs})
        table = np.full((len(rows), len(cols)), np.nan)
        for run, mean in zip(runs, means):
            table[rows.index(run.values[names[0]]), cols.index(run.values[names[1]])] = mean
        return plots.plot_heatmap(table, rows, cols, names, path, title)
    return plots.plot_config_means(labels, means, [stuck(run.seed_means) for run in runs], path,
                                   title, names[0] if len(names) == 1 else "configuration")


def sweep_summary_markdown(runs: list[SweepRun]) -> str:
    names = list(runs[0].values)
    return md_table([*names, *(c[1] for c in runs[0].judged)],
                    [[*(f"{v:g}" if isinstance(v, float) else v for v in run.values.values()),
                      *(c[3] for c in run.judged)] for run in runs])


def write_sweep_report(runs: list[SweepRun], seed_spec: str, out: Path) -> tuple[Path, Path]:
    """sweep.png and sweep_summary.md (what was swept, on what, the table and the figure)."""
    base, names = runs[0].params, list(runs[0].values)
    encoded = ",".join(base.state_vars)
    trials = runs[0].steps.shape[1]
    figure = plot_sweep(runs, out / "sweep.png", f"Sweep of {', '.join(names)}: {encoded}, "
                        f"{len(runs[0].seeds)} seeds x {trials} trials")
    defaults = Params().to_dict()
    fixed = [f"{k}={v}" for k, v in sorted(base.to_dict().items())
             if k not in (*names, "trials", "nsv", "state_vars") and v != defaults[k]]
    summary = out / "sweep_summary.md"
    summary.write_text(
        f"# Sweep of {', '.join(names)}\n\n"
        f"State variables {encoded}; seeds {seed_spec} ({len(runs[0].seeds)}) x {trials} trials; "
        f"the other parameters: {', '.join(fixed) or 'the paper defaults'}. Cells: the mean over "
        f"the seeds of the per-seed mean steps, and "
        + (f"the seeds below {STUCK_BELOW:,}" if base.protocol != "gymnasium" else
           "(CartPole-v1's protocol) the seeds that solved it (their last 100 episodes' returns "
           "averaging 475) and the median episodes it took them")
        + ". Per-trial steps: sweep_<configuration>.csv.\n\n"
        f"{sweep_summary_markdown(runs)}\n\n![sweep]({figure.name})\n")
    return figure, summary


# ---- the one-at-a-time table -------------------------------------------------------------------

def scaled(name: str, base: Params, factor: float):
    """A parameter at `factor` times its value in `base` (integers rounded, at least 1)."""
    value = (base.n_segments if name == "segments" else getattr(base, name)) * factor
    return max(1, int(round(value))) if name in INTEGER else value


def one_at_a_time_params(base: Params, name: str, factor: float) -> Params:
    """`base` with one parameter scaled; w_max carries the initial weights along (w_base and
    w_range keep their ratio to it, so they stay below it)."""
    change = {name: scaled(name, base, factor)}
    if name == "w_max":
        change.update(w_base=base.w_base * factor, w_range=base.w_range * factor)
    return base.replace(**change)


@dataclass
class Sensitivity:
    base: Params
    label: str  # e.g. "1 SV"
    baseline: np.ndarray  # per-seed means at Table 2
    rows: dict[tuple[str, float], np.ndarray]  # (parameter, factor) -> per-seed means


def sensitivity(bases: list[tuple[str, Params]], seeds) -> list[Sensitivity]:
    jobs = [(label, base, name, factor) for label, base in bases
            for name in (None, *SWEPT) for factor in ((1.0,) if name is None else FACTORS)]
    results: dict[str, Sensitivity] = {}
    for label, base, name, factor in progress(jobs, "sensitivity"):
        p = base if name is None else one_at_a_time_params(base, name, factor)
        means = run_batch(seeds, p).steps.mean(axis=1)
        if name is None:
            results[label] = Sensitivity(base, label, means, {})
        else:
            results[label].rows[(name, factor)] = means
    return list(results.values())


def relative_change(s: Sensitivity, name: str, factors) -> float:
    """The largest change of the mean over the seeds, as a fraction of the baseline mean."""
    base = s.baseline.mean()
    return max(abs(s.rows[(name, f)].mean() - base) / base for f in factors)


def write_sensitivity(results: list[Sensitivity], out: Path) -> Path:
    rows = []
    for s in results:
        rows.append([s.label, "(Table 2)", 1, round(float(s.baseline.mean()), 2),
                     stuck(s.baseline)])
        rows += [[s.label, name, factor, round(float(m.mean()), 2), stuck(m)]
                 for (name, factor), m in s.rows.items()]
    return write_csv(out / "sensitivity.csv", ["encoding", "parameter", "factor", "mean_steps",
                                               f"seeds_below_{STUCK_BELOW}"], rows)


def insensitive(s: Sensitivity) -> list[str]:
    """The parameters that halving or doubling moves by less than INSENSITIVE_WITHIN."""
    return [n for n in SWEPT if relative_change(s, n, (0.5, 2.0)) < INSENSITIVE_WITHIN]


def sensitivity_markdown(results: list[Sensitivity], n_seeds: int) -> str:
    md = ["## Sensitivity to the Table 2 parameters\n"]
    md.append(f"Each parameter alone at {', '.join(f'{f:g}' for f in FACTORS)} times its Table 2 "
              f"value (segments: of the paper's count; integers rounded; w_max carries the "
              f"initial weights with it), {n_seeds} seeds × {TRIALS} trials. Cells: mean over "
              f"the seeds of the per-seed mean steps, seeds below {STUCK_BELOW:,} in brackets. "
              f"`python -m clnn_ros.reproduce sweep` runs any such grid.\n")
    for s in results:
        header = ["parameter", "Table 2 value", *(f"× {f:g}" for f in FACTORS),
                  "largest change at × 1/2 and × 2"]
        rows = []
        for name in SWEPT:
            value = s.base.n_segments if name == "segments" else getattr(s.base, name)
            rows.append([name, f"{value:g}",
                         *(f"{s.rows[(name, f)].mean():,.0f} ({stuck(s.rows[(name, f)])})"
                           for f in FACTORS),
                         f"{relative_change(s, name, (0.5, 2.0)):.0%}"])
        md.append(f"**{s.label}** (Table 2: mean {s.baseline.mean():,.0f}, "
                  f"{stuck(s.baseline)} seeds below {STUCK_BELOW:,}):\n")
        md.append(md_table(header, rows) + "\n")
    md.append(sensitivity_verdict(results) + "\n")
    return "\n".join(md)


def sensitivity_verdict(results: list[Sensitivity]) -> str:
    """Whether the paper's claim holds, by the INSENSITIVE_WITHIN rule, per encoding."""
    lines = [f"**The paper's claim** (\"relatively insensitive\"), read as: halving or doubling "
             f"any one parameter moves the mean by less than {INSENSITIVE_WITHIN:.0%}."]
    for s in results:
        calm = insensitive(s)
        moved = [n for n in SWEPT if n not in calm]
        verdict = "holds" if not moved else ("holds for " + ", ".join(calm) if calm else
                                             "does not hold for any parameter")
        lines.append(f"{s.label}: it {verdict}" + (
            f"; not for {', '.join(f'{n} ({relative_change(s, n, (0.5, 2.0)):.0%})' for n in moved)}"
            if moved and calm else "") + ".")
    return " ".join(lines)


def check_sweep_names(grid: dict[str, list]) -> None:
    """Only model parameters are swept (trials and seeds are the sweep's own options)."""
    known = set(Params().to_dict()) - {"trials"}
    for name in grid:
        if name not in known:
            raise ParamError(f"--param {name}: not a model parameter; known: "
                             f"{', '.join(sorted(known))}")
