"""Batch engine: many episodes (seeds) at once, compiled with numba, one seed per thread.

It runs the core's own code, compiled: the physics, the encoder and every part of the learning
rule (inference, tagging, punishment, reward, counter decay, the success counter: the
`register_jitable` functions of clnn_ros.core.rln). What is its own is only the episode loop
and one shortcut: the network's decision for each input pattern is cached and recomputed only
when the weights change (a punishment or a reward), except with `tie_break="random"`, which
draws on every tie.

tests/test_batch.py proves it equal to the reference core (clnn_ros.core) trial by trial and in
the final weights, bit for bit, for every option value.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numba
import numpy as np

from .core.encoder import Encoder, encode_active
from .core.episode import angle_grid, seed_setup
from .core.params import Params
from .core.physics import CONTINUE, cartpole_step, physics_constants
from .core.rln import (NONE, TIE_RANDOM, Rule, infer, outcome, response_space, restart_counters,
                       tag_action_path, trial_start_count, update)


@numba.njit(cache=True, _nrt=False)
def _fill_decisions(weights, offsets, radix, rule, rng, active, responses, decisions):
    """Cache the network decision for every input pattern (mixed-radix index over variables)."""
    n_vars = offsets.shape[0]
    for pattern in range(decisions.shape[0]):
        rest = pattern
        for v in range(n_vars - 1, -1, -1):
            active[v] = offsets[v] + rest % radix[v]
            rest //= radix[v]
        decisions[pattern] = infer(weights, active, rule.tie_break, rng, responses)


@numba.njit(cache=True)
def run_episode_kernel(weights, angles, constants, force, components, edges, offsets, max_steps,
                       rule, learn, rng, steps_out, status_out):
    """One episode in place: `weights` end as the final weights, per-trial results in the outputs."""
    n_segments, n_inputs = weights.shape[1], weights.shape[2]
    n_vars = components.shape[0]
    radix = np.empty(n_vars, dtype=np.int64)
    for v in range(n_vars):
        radix[v] = (offsets[v + 1] if v + 1 < n_vars else n_inputs) - offsets[v]
    n_patterns = 1
    for v in range(n_vars):
        n_patterns *= radix[v]
    _run_trials(weights, angles, constants, force, components, edges, offsets, max_steps, rule,
                learn, rng, steps_out, status_out, radix, np.empty((n_patterns, 3), np.int64),
                np.empty((2, n_segments, n_inputs), np.int64), np.empty((2, n_segments), np.int64),
                np.zeros((2, n_segments, n_inputs), np.uint8), np.empty(n_vars, np.int64),
                response_space(n_segments))


# No reference counting in the tick loop: it would cost more than the tick's own work. All the
# arrays it uses are made by run_episode_kernel.
@numba.njit(cache=True, _nrt=False)
def _run_trials(weights, angles, constants, force, components, edges, offsets, max_steps, rule,
                learn, rng, steps_out, status_out, radix, decisions, punish_tagged_at,
                reward_tagged_at, eligible, active, responses):
    n_vars = components.shape[0]
    use_cache = rule.tie_break != TIE_RANDOM
    if use_cache:
        _fill_decisions(weights, offsets, radix, rule, rng, active, responses, decisions)
    now = 0  # the clock of the decay counters
    successes = 0
    for trial in range(angles.shape[0]):
        restart_counters(punish_tagged_at, reward_tagged_at, eligible)
        successes = trial_start_count(successes, rule)
        x, x_dot, theta, theta_dot = 0.0, 0.0, angles[trial], 0.0
        t = 0
        status = CONTINUE
        while t < max_steps:
            encode_active((x, x_dot, theta, theta_dot), components, edges, offsets, active)
            if use_cache:
                pattern = 0
                for v in range(n_vars):
                    pattern = pattern * radix[v] + active[v] - offsets[v]
                neuron, s0, s1 = decisions[pattern, 0], decisions[pattern, 1], decisions[pattern, 2]
            else:
                neuron, s0, s1 = infer(weights, active, rule.tie_break, rng, responses)
            tag_action_path(punish_tagged_at, reward_tagged_at, eligible, neuron, (s0, s1),
                            active, now, rule)
            x, x_dot, theta, theta_dot, status = cartpole_step(
                x, x_dot, theta, theta_dot, force if neuron == 1 else -force, constants)
            kind, successes = outcome(successes, status != CONTINUE, rule)
            if learn:
                now = update(kind, weights, punish_tagged_at, reward_tagged_at, eligible, active,
                             now, rule)
                if kind != NONE and use_cache:
                    _fill_decisions(weights, offsets, radix, rule, rng, active, responses,
                                    decisions)
            if status != CONTINUE:
                break
            t += 1
        steps_out[trial] = t
        status_out[trial] = status


@numba.njit(parallel=True, cache=True)
def _run_many(weights, angles, constants, force, components, edges, offsets, max_steps, rule,
              learn, rng, steps_out, status_out):
    for k in numba.prange(weights.shape[0]):
        run_episode_kernel(weights[k], angles[k], constants, force, components, edges, offsets,
                           max_steps, rule, learn, rng[k], steps_out[k], status_out[k])


@dataclass
class BatchResult:
    seeds: np.ndarray  # (S,)
    initial_angles: np.ndarray  # (S, trials) deg
    steps: np.ndarray  # (S, trials) successful steps
    end_status: np.ndarray  # (S, trials)
    final_weights: np.ndarray  # (S, 2, q, n_inputs)
    wall_s: float


def run_batch(seeds, p: Params, weights: np.ndarray | None = None, angles: np.ndarray | None = None,
              learn: bool = True) -> BatchResult:
    """Run one episode per seed (the core's seed protocol), in parallel over seeds.
    `weights` (2, q, n) and `angles` (trials,) override every seed's own."""
    seeds = np.asarray(list(seeds), dtype=np.int64)
    setups = [seed_setup(int(s), p) for s in seeds]
    all_weights = np.stack([w if weights is None else np.asarray(weights, np.float64)
                            for w, _ in setups])
    all_angles = np.stack([a if angles is None else np.asarray(angles, np.float64)
                           for _, a in setups])
    components, edges, offsets = Encoder.from_params(p).arrays
    rng = seeds.astype(np.uint64).reshape(-1, 1).copy()
    steps = np.zeros(all_angles.shape, dtype=np.int64)
    status = np.zeros(all_angles.shape, dtype=np.int64)
    start = time.perf_counter()
    _run_many(all_weights, all_angles, physics_constants(p), float(p.force), components, edges,
              offsets, p.max_steps, Rule.from_params(p), learn, rng, steps, status)
    wall = time.perf_counter() - start
    return BatchResult(seeds, all_angles, steps, status, all_weights, wall)


def evaluate_weights_batch(weights: np.ndarray, p: Params) -> BatchResult:
    """Fixed weights, one trial per grid angle (Figures 8 and 13), compiled."""
    return run_batch([0], p, weights=weights, angles=angle_grid(p), learn=False)
