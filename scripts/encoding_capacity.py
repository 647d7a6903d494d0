"""What an encoding lets any policy reach on a task, the rule aside (issue 46): the best table
policy over its input patterns, played frozen by the network itself.

    .venv/bin/python scripts/encoding_capacity.py gymnasium:InvertedPendulum-v5 --actions=-1,1 \
        --state-vars hinge_angle,hinge_angular_velocity,slider_velocity \
        --edges 'hinge_angle:0;hinge_angular_velocity:-0.1745,0.1745;slider_velocity:-0.2,0.2'

A 1-hot encoding puts each state in one input pattern (one interval per variable), so the
policies it admits are the tables pattern -> action. Each table is written into the weights of a
network with one segment per pattern (weight w_max on the pattern's inputs, 0 elsewhere: only
that segment responds fully), and the task batch engine plays it frozen from the task's own
starts (clnn_ros.task_batch, learn off). The search: every table where there are few, else
hill climbing (change one pattern's action while the mean return grows) from random tables or
a given one. Where every table was played and none reaches the task's threshold, no rule can
solve the task in this encoding (on these starts); a climb's best is a lower bound only.
Also measured: the tables one change away from the best (their median and best mean return),
how sharp its peak is. Prints one line per encoding, appended to --csv where given.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import sys
from pathlib import Path

import numpy as np

from clnn_ros.core.encoder import Encoder
from clnn_ros.core.episode import seed_setup
from clnn_ros.core.params import ParamError
from clnn_ros.core.presets import preset_values
from clnn_ros.core.rln import infer, response_space
from clnn_ros.core.rule import Rule
from clnn_ros.reproduce.common import parse_seeds
from clnn_ros.task_batch import compiles, run_compiled_task_episode
from clnn_ros.tasks.gymnasium_task import make, task_params

EXHAUSTIVE = 4096  # tables: at most this many are all played


def table_weights(table: tuple, radix: list[int], offsets: np.ndarray, n_actions: int,
                  n_inputs: int, w_max: float, n_segments: int = 0) -> np.ndarray:
    """The weights that play `table` (an action per pattern, patterns in mixed-radix order):
    neuron table[k]'s segment k holds w_max on pattern k's inputs (`n_segments` more than the
    patterns: the others all 0)."""
    weights = np.zeros((n_actions, max(len(table), n_segments), n_inputs))
    for k, (pattern, action) in enumerate(zip(itertools.product(*map(range, radix)), table)):
        for variable, interval in enumerate(pattern):
            weights[action, k, offsets[variable] + interval] = w_max
    return weights


def played_table(weights: np.ndarray, radix: list[int], offsets: np.ndarray,
                 rule: Rule) -> tuple:
    """The action the network picks for each pattern (the core's inference)."""
    responses, winners = response_space(*weights.shape[:2]), np.zeros(weights.shape[0], np.int64)
    return tuple(int(infer(weights, np.array([offsets[v] + i for v, i in enumerate(pattern)]),
                           rule, np.zeros(1, np.uint64), responses, winners))
                 for pattern in itertools.product(*map(range, radix)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("task", help="gymnasium:ID of a task whose step is compiled")
    parser.add_argument("--actions", default=None, help="a Box action space's values")
    parser.add_argument("--state-vars", required=True)
    parser.add_argument("--edges", required=True, help="variable_edges, e.g. 'a:0;b:-1,1'")
    parser.add_argument("--seeds", default="200,201",
                        help="the starts' seeds (selection seeds: 128-255)")
    parser.add_argument("--episodes", type=int, default=10, help="per seed and table")
    parser.add_argument("--restarts", type=int, default=3,
                        help="hill climbing's starts (the first: --start's table where given)")
    parser.add_argument("--start", default="", help="hill climbing's first start: a table, an "
                        "action per pattern in mixed-radix order, e.g. 0022 (else random)")
    parser.add_argument("--learn", type=int, default=0, metavar="EPISODES",
                        help="also learn this long with the rule (the preset's values) from "
                             "each seed's own weights, and from the best table's (a segment per "
                             "pattern at least), on --learn-seeds")
    parser.add_argument("--margin", type=float, default=None,
                        help="--learn from a table written as this much above each seed's own "
                             "initial weights (on its pattern's segment) instead of at w_max: "
                             "within the rule's reach")
    parser.add_argument("--preset", default=None, help="the rule's values for --learn")
    parser.add_argument("--learn-seeds", default="128-135")
    parser.add_argument("--csv", type=Path, default=None)
    args = parser.parse_args(argv)
    try:
        task, env = make(args.task, args.actions)
        if not compiles(task):
            raise ParamError(f"{args.task}: its step is not compiled (clnn_ros.tasks.compiled)")
        p = task_params(task, {"state_vars": args.state_vars, "variable_edges": args.edges})
        seeds = [int(s) for s in args.seeds.split(",")]
        learn_seeds = parse_seeds(args.learn_seeds)
        learning = task_params(task, {**(preset_values(args.preset) if args.preset else {}),
                                      "state_vars": args.state_vars,
                                      "variable_edges": args.edges,
                                      "trials": str(max(args.learn, 1))})
        encoder = Encoder.from_params(p, task.names, task.units)
        offsets, n_inputs = encoder.arrays[2], encoder.n_inputs
        radix = [int(b - a) for a, b in zip(offsets, [*offsets[1:], n_inputs])]
        n_patterns, n_actions = int(np.prod(radix)), len(task.actions)
        if args.restarts < 1:
            raise ParamError(f"--restarts {args.restarts}: hill climbing needs 1 start at least "
                             f"(the first is --start's table where given)")
        if args.start and (len(args.start) != n_patterns or
                           any(a not in "0123456789"[:n_actions] for a in args.start)):
            raise ParamError(f"--start {args.start}: a table is {n_patterns} actions "
                             f"(0-{n_actions - 1}), one per pattern")
    except (ParamError, ValueError) as error:
        print(f"encoding_capacity: error: {error}", file=sys.stderr)
        return 2
    played = p.replace(segments=n_patterns, trials=args.episodes)

    def mean_return(table: tuple) -> float:
        weights = table_weights(table, radix, offsets, n_actions, n_inputs, played.w_max)
        return float(np.mean([run_compiled_task_episode(seed, played, task, env, learn=False,
                                                        weights=weights.copy()).returns
                              for seed in seeds]))

    if n_actions ** n_patterns <= EXHAUSTIVE:
        search = "every table"
        best = max(((mean_return(t), t) for t in itertools.product(range(n_actions),
                                                                   repeat=n_patterns)))
    else:
        search = f"hill climbing, starts: {args.restarts}" + (
            " (the first: --start's table)" if args.start else " (random tables)")
        rng, best = np.random.default_rng(0), (-np.inf, ())
        for restart in range(args.restarts):
            table = [int(a) for a in args.start] if args.start and restart == 0 else \
                list(rng.integers(0, n_actions, n_patterns))
            score, improved = mean_return(tuple(table)), True
            while improved:
                improved = False
                for k, action in itertools.product(range(n_patterns), range(n_actions)):
                    if table[k] == action:
                        continue
                    trial_table = [*table[:k], action, *table[k + 1:]]
                    if (trial := mean_return(tuple(trial_table))) > score:
                        table, score, improved = trial_table, trial, True
            best = max(best, (score, tuple(int(a) for a in table)))
    # How sharp the best table's peak is: its tables one change away (a learner that changes
    # one pattern's action at a time sees no slope where they all play far worse).
    neighbours = [mean_return((*best[1][:k], action, *best[1][k + 1:]))
                  for k, action in itertools.product(range(n_patterns), range(n_actions))
                  if best[1][k] != action]
    row = {"task": task.name, "state_vars": args.state_vars, "variable_edges": args.edges,
           "patterns": n_patterns, "search": search,
           "episodes": args.episodes * len(seeds), "best mean return": round(best[0], 1),
           "threshold": task.reward_threshold, "best table": "".join(map(str, best[1])),
           "one change away: median": round(float(np.median(neighbours)), 1),
           "one change away: best": round(max(neighbours), 1)}
    if args.learn:
        row.update(learned(best[1], learning, task, env, learn_seeds, radix, offsets,
                           args.margin))
    print(", ".join(f"{k}: {v}" for k, v in row.items()))
    if args.csv is not None:
        new = not args.csv.exists()
        with open(args.csv, "a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(row))
            if new:
                writer.writeheader()
            writer.writerow(row)
    return 0


def learned(best: tuple, p, task, env, seeds, radix: list[int], offsets: np.ndarray,
            margin: float | None = None) -> dict:
    """The rule on the encoding: from the best table's weights (a segment per pattern at least)
    and, the control, from the reversed table's (every action mirrored: a table written at
    w_max is out of the rule's reach in these episodes if that one stays as bad; `margin`
    writes both as that much above each seed's own initial weights instead), and does it find
    the best table (`p` as it is, from each seed's own weights: the table it ends with)?"""
    wide = p.replace(segments=max(p.n_segments, len(best)))

    def weights(table: tuple, seed: int) -> np.ndarray:
        if margin is None:
            return table_weights(table, radix, offsets, p.n_actions, p.n_inputs, p.w_max,
                                 wide.n_segments)
        return seed_setup(seed, wide)[0] + margin * table_weights(
            table, radix, offsets, p.n_actions, p.n_inputs, 1.0, wide.n_segments)

    def from_table(table: tuple) -> float:
        return round(float(np.mean([run_compiled_task_episode(
            seed, wide, task, env, weights=weights(table, seed)).returns[-100:].mean()
            for seed in seeds])), 1)
    own = [run_compiled_task_episode(seed, p, task, env) for seed in seeds]
    unlike = [sum(a != b for a, b in zip(played_table(r.final_weights, radix, offsets,
                                                      Rule.from_params(p)), best))
              for r in own]
    return {"learning episodes": p.trials, "learning seeds": len(seeds),
            "table written": "at w_max" if margin is None else f"+{margin:g} on the seed's",
            "from the best table: last 100": from_table(best),
            "from the reversed table: last 100": from_table(
                tuple(p.n_actions - 1 - action for action in best)),
            "from the seeds' weights: last 100": round(float(np.mean(
                [r.returns[-100:].mean() for r in own])), 1),
            "patterns unlike the best table's (median)": float(np.median(unlike))}


if __name__ == "__main__":
    raise SystemExit(main())
