"""A grid of parameter values on any task but the cart-pole (`clnn-reproduce sweep --task
gymnasium:ID --param NAME=V1,V2 ...`): every configuration x every seed, the pure core's
episodes in worker processes (task_learning.run_task_jobs: kept as they finish, an
interrupted sweep resumes), judged at the task's own threshold."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.params import Params, variable_edges_text
from ..core.solving import WINDOW
from ..core.task_episode import TaskEpisodeResult
from ..figures import plot_task_returns
from ..tasks.gymnasium_task import env_id, make, task_params
from .common import md_table, write_csv
from .sensitivity import sweep_configs
from .task_learning import TaskRun, run_task_jobs, solving


def sweep_task(task_name: str, actions: str | None, grid: dict[str, list], seeds,
               values: dict[str, str], store: Path, workers: int) -> list[tuple[dict, TaskRun]]:
    """(the swept values, the run) of every configuration: the grid over the task's Params (its
    first encoding, then `values`), all validated before any runs."""
    task, _ = make(task_name, actions)
    configs = sweep_configs(task_params(task, values), grid)
    for _, p in configs:
        task.check(p)
    seeds = [int(seed) for seed in seeds]
    results = iter(run_task_jobs(task_name, actions, [(p, seed) for _, p in configs
                                                      for seed in seeds], store, workers))
    return [(swept, TaskRun(task, p, [TaskEpisodeResult(seed, **next(results))
                                      for seed in seeds])) for swept, p in configs]


COLUMNS = ("seeds", "solved", "median episodes to solve", "median steps to solve",
           "mean return", f"mean of the last {WINDOW}")


def measures(run: TaskRun) -> list:
    """One configuration's row of COLUMNS: over its seeds."""
    solved = [at for at in (solving(e, run.task.reward_threshold) for e in run.episodes)
              if at is not None]
    to_solve = [f"{m:g}" for m in np.median(solved, axis=0)] if solved else ["-", "-"]
    return [len(run.episodes), len(solved), *to_solve,
            f"{np.mean([e.returns.mean() for e in run.episodes]):.1f}",
            f"{np.mean([e.returns[-WINDOW:].mean() for e in run.episodes]):.1f}"]


def write_task_sweep(runs: list[tuple[dict, TaskRun]], out: Path) -> list[Path]:
    """sweep_<task>.csv (a row per configuration), sweep_<task>.png (each configuration's
    learning curve) and sweep_<task>.md (what was swept, the table, the figure)."""
    names = list(runs[0][0])
    task, first = runs[0][1].task, runs[0][1]
    rows = [[*swept.values(), *measures(run)] for swept, run in runs]
    name = env_id(task.name)
    csv = write_csv(out / f"sweep_{name}.csv", [*names, *COLUMNS], rows)
    label = (lambda swept: ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                                     for k, v in swept.items()))
    figure = plot_task_returns({label(swept): np.array([e.returns for e in run.episodes])
                                for swept, run in runs}, out / f"sweep_{name}.png",
                               f"{task.name}, sweep of {', '.join(names)}", task.reward_threshold)
    defaults = Params().to_dict()
    shown = {**first.params.to_dict(), "state_vars": ",".join(first.params.state_vars),
             "variable_edges": variable_edges_text(first.params.variable_edges)}
    fixed = [f"{k}={v}" for k, v in sorted(shown.items())
             if k not in (*names, "trials", "nsv", "task") and v != defaults[k]]
    summary = out / f"sweep_{name}.md"
    summary.write_text(
        f"# {task.name}: sweep of {', '.join(names)}\n\n"
        f"{len(first.episodes)} seeds x {first.params.trials} episodes each; the other "
        f"parameters: {', '.join(fixed)}. Solved: the first episode whose last {WINDOW} returns "
        f"average the task's threshold ({task.reward_threshold}) or more.\n\n"
        + md_table([*names, *COLUMNS], rows)
        + f"\n\n![sweep]({figure.name})\n\nPer configuration: [{csv.name}]({csv.name}).\n")
    return [csv, figure, summary]
