"""Learning any task but the cart-pole (`clnn-reproduce learn --task gymnasium:ID`): each seed's
episode with the core (core.task_episode, its rule's costly functions compiled by the batch
engine: the same results) in the task's own environment, or all compiled where the task's step
is (clnn_ros.task_batch: the same results), the seeds shared out to worker processes. Judged as
the field judges the task: solved at the first episode whose last 100 returns average its
threshold or more."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..batch import COMPILED_KERNELS
from ..core.params import Params
from ..core.solving import WINDOW, solved_episode
from ..core.task import Task
from ..core.task_episode import TaskEpisodeResult, run_task_episode
from ..task_batch import compiles, run_compiled_task_episode
from ..tasks.gymnasium_task import env_id, make, task_params
from ..figures import plot_task_returns
from .common import load_stored, md_table, progress, store_arrays, store_path, write_csv
from .workers import in_workers


@dataclass
class TaskRun:
    task: Task
    params: Params
    episodes: list[TaskEpisodeResult]  # one per seed

    @property
    def name(self) -> str:
        return env_id(self.task.name)


def learn_task(task_name: str, actions: str | None, seeds, values: dict[str, str],
               base: Params, store: Path, workers: int) -> TaskRun:
    """Every seed's episode of the task, its Params the task's first encoding, then `values`
    over `base` (run_task_jobs)."""
    task, _ = make(task_name, actions)
    p = task_params(task, values, base)
    seeds = [int(seed) for seed in seeds]
    results = run_task_jobs(task_name, actions, [(p, seed) for seed in seeds], store, workers)
    return TaskRun(task, p, [TaskEpisodeResult(seed, **arrays)
                             for seed, arrays in zip(seeds, results)])


def run_task_jobs(task_name: str, actions: str | None, jobs: list[tuple[Params, int]],
                  store: Path, workers: int) -> list[dict]:
    """The arrays of each job's episode (its Params, its seed), in the jobs' order: run in
    `workers` processes, each kept in `store` as it finishes (a job stored there is not run
    again: an interrupted run resumes)."""
    paths = {(p, seed): store_path(store, f"{env_id(task_name)}_seed_{seed}",
                                   [task_name, actions, p.to_dict(), seed]) for p, seed in jobs}
    results = {job: load_stored(path) for job, path in paths.items() if path.exists()}
    todo = [(task_name, actions, p, seed) for p, seed in paths if (p, seed) not in results]
    if todo:
        finished = in_workers(task_seed, todo, workers)
        for (_, _, p, seed), arrays in progress(finished, env_id(task_name)):
            results[p, seed] = arrays
            store_arrays(paths[p, seed], arrays)
    return [results[job] for job in jobs]


def task_seed(task_name: str, actions: str | None, p: Params, seed: int) -> dict:
    """One seed's episode of the task (in a worker process), as arrays."""
    task, env = make(task_name, actions)
    result = task_episode(seed, p, task, env)
    return dict(steps=result.steps, returns=result.returns, terminated=result.terminated,
                final_weights=result.final_weights)


def task_episode(seed: int, p: Params, task: Task, env, learn: bool = True,
                 weights: np.ndarray | None = None) -> TaskEpisodeResult:
    """core.task_episode.run_task_episode, the fastest way: all compiled where the task's step
    is (clnn_ros.task_batch), else Gymnasium's step with the rule compiled (the same
    results)."""
    if compiles(task):
        return run_compiled_task_episode(seed, p, task, env, learn, weights)
    return run_task_episode(seed, p, task, env, learn, weights, kernels=COMPILED_KERNELS)


def write_task_outputs(run: TaskRun, out: Path) -> list[Path]:
    """learn_<task>.csv (a row per trial), final_weights_<task>.npz, the learning curve
    learn_<task>.png and the summary learn_<task>.md."""
    rows = ([e.seed, trial, int(e.steps[trial]), repr(float(e.returns[trial])),
             int(e.terminated[trial])] for e in run.episodes for trial in range(len(e.steps)))
    out.mkdir(parents=True, exist_ok=True)
    npz = out / f"final_weights_{run.name}.npz"
    returns = np.array([e.returns for e in run.episodes])
    np.savez_compressed(npz, seeds=[e.seed for e in run.episodes],
                        final_weights=np.array([e.final_weights for e in run.episodes]),
                        steps=np.array([e.steps for e in run.episodes]), returns=returns,
                        terminated=np.array([e.terminated for e in run.episodes]),
                        task=run.task.name, params=json.dumps(run.params.to_dict()))
    csv = write_csv(out / f"learn_{run.name}.csv",
                    ["seed", "trial", "steps", "return", "terminated"], rows)
    figure = plot_task_returns({f"{len(returns)} seeds": returns}, out / f"learn_{run.name}.png",
                               f"{run.task.name}, the RLN agent", run.task.reward_threshold)
    summary = out / f"learn_{run.name}.md"
    summary.write_text(f"# {run.task.name}: the RLN agent learning\n\n"
                       + "\n".join(summary_lines(run, markdown=True))
                       + f"\n\n![learning curve]({figure.name})\n\nPer trial: [{csv.name}]"
                         f"({csv.name}); final weights: {npz.name}.\n")
    return [csv, npz, figure, summary]


def summary_lines(run: TaskRun, markdown: bool = False) -> list[str]:
    """What the run shows: the task, each seed's returns, and how many seeds solved it (a
    Markdown table with `markdown`, else aligned text)."""
    task = run.task
    header = ["seed", "mean return", f"last {WINDOW}", "solved at episode"]
    lines = [f"{task.name}: {len(run.episodes)} seeds x {run.params.trials} episodes; "
             f"{len(task.actions)} actions ({', '.join(task.action_labels)}); encoded: "
             f"{', '.join(run.params.state_vars)}; reward mapping {run.params.reward_mapping}",
             ""]
    solved = [solving(e, task.reward_threshold) for e in run.episodes]
    rows = [[e.seed, f"{e.returns.mean():.1f}", f"{e.returns[-WINDOW:].mean():.1f}",
             "-" if at is None else at[0]] for e, at in zip(run.episodes, solved)]
    widths = (6, 12, 10, 18)
    lines += md_table(header, rows).splitlines() if markdown else \
        [" ".join(f"{cell:>{width}}" for cell, width in zip(row, widths))
         for row in [header, *rows]]
    return lines + ["", solved_line(task, solved)]


def solving(episode: TaskEpisodeResult, threshold: float | None) -> tuple[int, int] | None:
    """(the episode it solved the task at, the environment steps up to it), or None."""
    at = None if threshold is None else solved_episode(episode.returns, threshold)
    return None if at is None else (at, int(episode.steps[:at].sum()))


def solved_line(task: Task, solved: list[tuple[int, int] | None]) -> str:
    """How many seeds solved the task (solving, per seed) and what it took them."""
    if task.reward_threshold is None:
        return f"{task.name} has no reward threshold: no seed is judged solved"
    line = (f"solved {task.name} (last {WINDOW} returns averaging {task.reward_threshold:g} or "
            f"more): {sum(at is not None for at in solved)} of {len(solved)} seeds")
    if any(at is not None for at in solved):
        episodes, steps = np.array([at for at in solved if at is not None]).T
        line += (f"; episodes to solve: median {np.median(episodes):g}; environment steps: "
                 f"median {np.median(steps):,.0f}")
    return line
