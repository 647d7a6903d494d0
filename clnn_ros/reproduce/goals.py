"""Beyond the paper: an agent a robot can use. Learning under Gymnasium's CartPole-v1 physics,
out of the paper's local optima, and the paper's own section 5 proposal (periodic
re-randomization of a few weights) measured; written to docs/LEARNING.md.

    python -m clnn_ros.reproduce goals [--out docs]

Every setting is chosen on the selection seeds and reported on other seeds (SELECT_SEEDS,
REPORT_SEEDS). Each run is stored once finished (OUT/data/goals/<run>.npz) and not run again
while its parameters and seeds are the same: an interrupted run resumes.

Here the study's runs; its settings are in goals_settings, what it measures in goals_measures,
its CSVs, figure and Markdown in goals_report.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import gymnasium
import numpy as np

from ..batch import evaluate_weights_batch, run_batch
from ..core.encoder import Encoder
from ..core.optimal import optimal_weights
from ..core.params import Params
from .common import progress, store_path, stored, stored_batch
from .goals_measures import HandMade, Outcome, Study, fig12_cells, fig12_params, play_rank, rank
from .goals_report import goals_markdown, plot_curves, write_goals
from .goals_settings import (CANDIDATE_PLAY_EPISODES, CANDIDATES, HAND_MADE, LAST_TRIALS,
                             LINEAR_RULE_GAINS, PLAY_EPISODES, PRESET_OF, REPORT_SEEDS,
                             SELECT_SEEDS, WORLDS, grid_label, grid_points, preset_params,
                             world_params)
from .gym_eval import GYM_ID, FrozenPolicy, LearnOutput, gym_eval, reset_seed

# What the command (reproduce/__main__.py) and tests/test_goals.py take from here.
__all__ = ["LAST_TRIALS", "PLAY_EPISODES", "REPORT_SEEDS", "SELECT_SEEDS", "WORLDS", "Outcome",
           "goals_markdown", "goals_study", "grid_points", "plot_curves", "preset_params",
           "world_params", "write_goals"]


def run_stored(world: str, label: str, p: Params, seeds, store: Path,
               play_episodes: int = 0) -> Outcome:
    """The batch engine's episodes (and with play_episodes their final weights played frozen in
    gymnasium), or those an earlier call stored for the same parameters and seeds."""
    seeds = np.asarray(list(seeds), dtype=np.int64)
    name = f"{world}_{label}"
    data = stored_batch(p, seeds, store, name)
    outcome = Outcome(world, label, p, seeds, data["steps"], data["end_status"],
                      data["final_weights"])
    if play_episodes:
        outcome.play = stored(
            store_path(store, name, [p.to_dict(), seeds.tolist(), "play", play_episodes]),
            lambda: dict(returns=gym_eval(LearnOutput(label, seeds, outcome.final_weights, p),
                                          play_episodes, 0)))["returns"]
    return outcome


def play_start_angles(seeds, episodes: int) -> np.ndarray:
    """(seeds, episodes) the pole angle (deg) gymnasium starts each play episode with."""
    with gymnasium.make(GYM_ID) as env:
        return np.array([[math.degrees(env.reset(seed=reset_seed(s, e, 0))[0][2])
                          for e in range(episodes)] for s in seeds])


def linear_rule_weights(p: Params) -> tuple[Params, np.ndarray]:
    """(p with a segment per input pattern, weights acting as the linear rule on each pattern's
    interval centres; an outer interval's centre lies one neighbouring width out)."""
    encoder = Encoder.from_params(p)
    _, _, offsets = encoder.arrays
    centres = []
    for edges in encoder.edges:
        width = (edges[-1] - edges[0]) / max(len(edges) - 1, 1) or 1.0
        bounds = (edges[0] - width, *edges, edges[-1] + width)
        centres.append([(a + b) / 2 for a, b in zip(bounds, bounds[1:])])
    patterns = list(itertools.product(*(range(len(c)) for c in centres)))
    p = p.replace(segments=len(patterns))
    weights = np.zeros((2, p.n_segments, p.n_inputs))
    for segment, pattern in enumerate(patterns):
        push = sum(LINEAR_RULE_GAINS[component] * centres[v][k]
                   for v, (component, k) in enumerate(zip(encoder.components, pattern)))
        inputs = [offsets[v] + k for v, k in enumerate(pattern)]
        weights[int(push > 0), segment, inputs] = p.w_max
    return p, weights


def goals_study(report_seeds, select_seeds, trials: int, episodes: int, store: Path,
                report_spec: str, select_spec: str) -> Study:
    def plays(world, count):
        return count if world == "gymnasium" else 0

    jobs = [(w, label, world_params(w, trials).replace(**changes))
            for w, label, changes in CANDIDATES]
    candidates = [run_stored(w, label, p, select_seeds, store,
                             plays(w, min(episodes, CANDIDATE_PLAY_EPISODES)))
                  for w, label, p in progress(jobs, "goals: candidates")]
    grid_jobs = [(w, point) for w in WORLDS for point in grid_points()]
    grid = [run_stored(w, grid_label(point), world_params(w, trials).replace(**point),
                       select_seeds, store) for w, point in progress(grid_jobs, "goals: grid")]
    reported = {}
    for w in progress(list(WORLDS), "goals: reported runs"):
        mine = [c for c in candidates if c.world == w]
        chosen = [("Table 2", world_params(w, trials)),
                  (f"preset {PRESET_OF[w]}", preset_params(w, trials)),
                  (f"best candidate: {min(mine, key=rank).label}", min(mine, key=rank).params)]
        if w == "gymnasium":
            best_play = min(mine, key=play_rank)
            chosen.append((f"best frozen play: {best_play.label}", best_play.params))
        best = min((g for g in grid if g.world == w), key=rank)
        chosen.append((f"re-randomized ({best.label})", best.params))
        unique = {}
        for label, p in chosen:  # a configuration twice (the preset is the best): shown once
            unique.setdefault(json.dumps(p.to_dict(), default=list), (label, p))
        reported[w] = [run_stored(w, label, p, report_seeds, store, plays(w, episodes))
                       for label, p in unique.values()]
    hand_made = []
    for label, changes in HAND_MADE:
        p, weights = linear_rule_weights(world_params("gymnasium", trials).replace(**changes))
        hand_made.append(HandMade(
            label, float(evaluate_weights_batch(weights, p).steps.mean()),
            gym_eval(LearnOutput(label, np.array([0]), weights[None], p), episodes, 0)[0]))
    fig7 = float(evaluate_weights_batch(optimal_weights(1), Params(nsv=1)).steps.mean())
    two_sv = min(reported["paper_2sv"][1:], key=rank)
    from_fig12 = fig12_params(two_sv)
    kept = stored(store_path(store, "paper_2sv_from Figure 12", [from_fig12.to_dict(),
                                                                  list(select_seeds)]),
                  lambda: dict(steps=run_batch(select_seeds, from_fig12,
                                               weights=optimal_weights(2)).steps))["steps"].mean()
    frozen_means = np.array([evaluate_weights_batch(w, two_sv.params).steps.mean()
                             for w in two_sv.final_weights])
    fig12 = fig12_cells(two_sv)
    differing = [sum(FrozenPolicy(two_sv.params, w, 0).actions[pattern] != action
                     for pattern, action in fig12.items()) for w in two_sv.final_weights]
    return Study(candidates, grid, reported, hand_made,
                 play_start_angles(report_seeds, episodes), fig7, float(kept),
                 float(np.mean(np.abs(frozen_means - fig7) < 1.0)), float(np.mean(differing)),
                 report_spec, select_spec)
