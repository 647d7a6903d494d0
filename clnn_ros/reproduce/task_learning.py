"""Learning any task but the cart-pole (`clnn-reproduce learn --task gymnasium:ID`): each seed's
episode with the pure core (core.task_episode) in the task's own environment, the seeds shared
out to worker processes (the batch engine is the cart-pole's). Judged as the field judges the task: solved at the first
episode whose last 100 returns average the task's threshold or more."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.params import Params
from ..core.solving import WINDOW, solved_episode
from ..core.task import Task
from ..core.task_episode import TaskEpisodeResult, run_task_episode
from ..tasks.gymnasium_task import env_id, make, task_params
from .common import load_stored, progress, store_arrays, store_path, write_csv
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
    over `base`; the seeds run in `workers` processes, each one's result kept in `store` as
    it finishes (a seed stored there is not run again: an interrupted run resumes)."""
    task, _ = make(task_name, actions)
    p = task_params(task, values, base)
    paths = {int(seed): store_path(store, f"{env_id(task_name)}_seed_{seed}",
                                   [task_name, actions, p.to_dict(), int(seed)])
             for seed in seeds}
    results = {seed: load_stored(path) for seed, path in paths.items() if path.exists()}
    todo = [(task_name, actions, p, seed) for seed in paths if seed not in results]
    if todo:
        finished = in_workers(task_seed, todo, workers)
        for (_, _, _, seed), arrays in progress(finished, env_id(task_name)):
            results[seed] = arrays
            store_arrays(paths[seed], arrays)
    return TaskRun(task, p, [TaskEpisodeResult(seed, **results[seed]) for seed in paths])


def task_seed(task_name: str, actions: str | None, p: Params, seed: int) -> dict:
    """One seed's episode of the task (in a worker process), as arrays."""
    task, env = make(task_name, actions)
    result = run_task_episode(seed, p, task, env)
    return dict(steps=result.steps, returns=result.returns, terminated=result.terminated,
                final_weights=result.final_weights)


def write_task_outputs(run: TaskRun, out: Path) -> list[Path]:
    """learn_<task>.csv (a row per trial) and final_weights_<task>.npz."""
    rows = ([e.seed, trial, int(e.steps[trial]), repr(float(e.returns[trial])),
             int(e.terminated[trial])] for e in run.episodes for trial in range(len(e.steps)))
    out.mkdir(parents=True, exist_ok=True)
    npz = out / f"final_weights_{run.name}.npz"
    np.savez_compressed(npz, seeds=[e.seed for e in run.episodes],
                        final_weights=np.array([e.final_weights for e in run.episodes]),
                        steps=np.array([e.steps for e in run.episodes]),
                        returns=np.array([e.returns for e in run.episodes]),
                        terminated=np.array([e.terminated for e in run.episodes]),
                        task=run.task.name, params=json.dumps(run.params.to_dict()))
    return [write_csv(out / f"learn_{run.name}.csv",
                      ["seed", "trial", "steps", "return", "terminated"], rows), npz]


def print_task_summary(run: TaskRun) -> None:
    task, threshold = run.task, run.task.reward_threshold
    print(f"{task.name}: {len(run.episodes)} seeds x {run.params.trials} episodes; "
          f"{len(task.actions)} actions ({', '.join(task.action_labels)}); encoded: "
          f"{', '.join(run.params.state_vars)}; reward mapping {run.params.reward_mapping}")
    print(f"{'seed':>6s} {'mean return':>12s} {'last 100':>10s} {'solved at':>10s}")
    solved = []
    for e in run.episodes:
        episode = None if threshold is None else solved_episode(e.returns, threshold)
        if episode is not None:
            solved.append((episode, int(e.steps[:episode].sum())))
        print(f"{e.seed:6d} {e.returns.mean():12.1f} {e.returns[-WINDOW:].mean():10.1f} "
              f"{'-' if episode is None else episode:>10}")
    if threshold is None:
        print(f"{task.name} has no reward threshold: no seed is judged solved")
        return
    line = (f"solved {task.name} (last {WINDOW} returns averaging {threshold:g} or more): "
            f"{len(solved)} of {len(run.episodes)} seeds")
    if solved:
        episodes, steps = np.array(solved).T
        line += (f"; episodes to solve: median {np.median(episodes):g}; environment steps: "
                 f"median {np.median(steps):,.0f}")
    print(line)
