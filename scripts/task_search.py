"""The search for a task's preset (issue 46), on the selection seeds only: a random search over
the task's space of candidate values (stage 1: few seeds), then the best candidates again on
every selection seed (stage 2). Every candidate's row is kept, the failures too.

    .venv/bin/python scripts/task_search.py gymnasium:Acrobot-v1 [--samples 48] [--trials 600]
                                            [--finalists 6] [--out docs/data]

Ranked by: seeds solved, then the median environment steps to solve (fewer first), then the mean
return of the last 100 episodes. The seeds are learned as `clnn-reproduce sweep --task` learns
them (kept in OUT/task_search_runs: an interrupted search resumes). Writes
OUT/task_search_<ID>.csv, a row per candidate and stage.
"""

from __future__ import annotations

import argparse
import random
import sys
from pathlib import Path

from clnn_ros.core.params import ParamError
from clnn_ros.core.task_episode import TaskEpisodeResult
from clnn_ros.reproduce.common import write_csv
from clnn_ros.reproduce.task_learning import TaskRun, run_task_jobs
from clnn_ros.reproduce.task_sweep import COLUMNS, measures
from clnn_ros.tasks.gymnasium_task import env_id, make, task_params

# Each task's space: a parameter -> its candidate values (text, as --option takes them). A
# candidate takes one value of each, drawn at random.
SPACES = {
    "gymnasium:Acrobot-v1": {
        "state_vars": ["theta1_dot", "theta1_dot,theta2_dot", "sin_theta1,theta1_dot,theta2_dot",
                       "cos_theta1,sin_theta1,cos_theta2,sin_theta2,theta1_dot,theta2_dot"],
        "variable_edges": ["cos_theta1:0;sin_theta1:0;cos_theta2:0;sin_theta2:0;theta1_dot:0;"
                           "theta2_dot:0",
                           "cos_theta1:0;sin_theta1:0;cos_theta2:0;sin_theta2:0;"
                           "theta1_dot:-1,0,1;theta2_dot:-1,0,1"],
        "omega": ["32", "64", "80", "100", "128", "160", "256"],
        "sigma": ["16", "32", "64", "128"],
        "punish": ["0.0078125", "0.03125"],
    },
    "gymnasium:MountainCar-v0": {
        "variable_edges": ["position:-0.5;velocity:0",
                           "position:-0.9,-0.5,-0.2;velocity:0",
                           "position:-0.9,-0.5,-0.2;velocity:-0.005,0,0.005",
                           "position:-1.0,-0.7,-0.5,-0.3,0;velocity:0",
                           "position:-0.9,-0.7,-0.5,-0.3,-0.1,0.1,0.3;velocity:0",
                           "position:-0.9,-0.6,-0.3,0,0.3;velocity:-0.01,0,0.01"],
        "omega": ["100", "110", "120", "130", "150"],
        "sigma": ["64", "128", "200"],
        "punish": ["0.0078125", "0.03125"],
        "rho_minus": ["0.00390625", "0.0625"],
        "segments": ["", "4", "16"],
        "explore": ["0", "0.01", "0.05"],
        "tagging": ["winner", "both_neurons"],
    },
    # from CartPole-v1's preset carried over (docs/TASKS.md: 442-476 after 800 episodes), actions
    # -1 and +1 N; all four variables (the slider's position too) or the three of CartPole-v1's
    "gymnasium:InvertedPendulum-v5": {
        "state_vars": ["hinge_angle,hinge_angular_velocity,slider_velocity",
                       "slider_position,hinge_angle,slider_velocity,hinge_angular_velocity"],
        "variable_edges": ["slider_position:-0.5,0.5;hinge_angle:0;slider_velocity:-0.2,0.2;"
                           "hinge_angular_velocity:-0.17453292519943295,0.17453292519943295",
                           "slider_position:0;hinge_angle:-0.02,0,0.02;slider_velocity:0;"
                           "hinge_angular_velocity:-0.17453292519943295,0.17453292519943295"],
        "segments": ["9", "16"],
        "omega": ["64", "96", "128", "192"],
        "sigma": ["32", "64", "128"],
        "punish": ["0.015625", "0.0625"],
        "rho_plus": ["0.0078125", "0.03125"],
        "rho_minus": ["0", "0.00390625"],
    },
}
SELECTION = range(128, 256)
STAGE_1_SEEDS = range(128, 136)
FINALISTS = 6


def candidates(space: dict, samples: int, draw: random.Random) -> list[dict]:
    """`samples` distinct candidates of the space, drawn in a fixed order."""
    found: list[dict] = []
    total = 1
    for values in space.values():
        total *= len(values)
    while len(found) < min(samples, total):
        candidate = {name: draw.choice(values) for name, values in space.items()}
        if candidate not in found:
            found.append(candidate)
    return found


def evaluate(task_name: str, configs: list[dict], seeds, trials: int, store: Path,
             workers: int) -> list[list]:
    """A row of measures (task_sweep.COLUMNS) per candidate, over `seeds`."""
    task, _ = make(task_name)
    params = [task_params(task, {"trials": str(trials), **{k: v for k, v in c.items() if v}})
              for c in configs]
    results = iter(run_task_jobs(task_name, None, [(p, s) for p in params for s in seeds], store,
                                 workers))
    return [measures(TaskRun(task, p, [TaskEpisodeResult(s, **next(results)) for s in seeds]))
            for p in params]


def rank(row: list) -> tuple:
    """Sort key of a row of measures: seeds solved, fewer steps to solve, the last 100's mean."""
    steps = float(row[3]) if row[3] != "-" else float("inf")
    return -row[1], steps, -float(row[5])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("task", choices=sorted(SPACES))
    parser.add_argument("--samples", type=int, default=48)
    parser.add_argument("--trials", type=int, default=600)
    parser.add_argument("--finalists", type=int, default=FINALISTS,
                        help="stage 1's best, run again on every selection seed")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="docs/data")
    args = parser.parse_args(argv)
    out = Path(args.out)
    space = SPACES[args.task]
    configs = candidates(space, args.samples, random.Random(46))
    try:
        stage_1 = evaluate(args.task, configs, STAGE_1_SEEDS, args.trials,
                           out / "task_search_runs", args.workers)
    except ParamError as error:
        print(f"task_search: error: {error}", file=sys.stderr)
        return 2
    order = sorted(range(len(configs)), key=lambda k: rank(stage_1[k]))
    finalists = order[:args.finalists]
    stage_2 = evaluate(args.task, [configs[k] for k in finalists], SELECTION, args.trials,
                       out / "task_search_runs", args.workers)
    rows = [[1, *configs[k].values(), *stage_1[k]] for k in order]
    rows += [[2, *configs[k].values(), *row] for k, row in
             sorted(zip(finalists, stage_2), key=lambda pair: rank(pair[1]))]
    csv = write_csv(out / f"task_search_{env_id(args.task)}.csv",
                    ["stage", *space, *COLUMNS], rows)
    best = min(zip(finalists, stage_2), key=lambda pair: rank(pair[1]))
    print(f"best on seeds {SELECTION.start}-{SELECTION.stop - 1}: {configs[best[0]]}: "
          f"{dict(zip(COLUMNS, best[1]))}")
    print(f"wrote {csv}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
