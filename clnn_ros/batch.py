"""Batch engine: many episodes (seeds) at once, compiled with numba, one seed per thread.

It runs the same physics and encoder code as the core (their functions are `register_jitable`)
and re-implements only the RLN bookkeeping, for speed:

* decay counters are kept lazily as the tick at which they were last set: a counter set to omega
  at tick t0 reads omega - (t - t0) at tick t, or 0 once that is <= 0; this is exactly the
  reference's "set, then decrement every tick", without touching every synapse every tick;
* the network's decision for each input pattern is cached and recomputed only when the weights
  change (a punishment or a reward), except with `tie_break="random"`, which draws on every tie.

tests/test_batch.py proves it equal to the reference core (clnn_ros.core) trial by trial and in
the final weights, bit for bit.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np

from .core.encoder import Encoder, encode_active
from .core.episode import angle_grid, seed_setup
from .core.params import TIE_BREAKS, Params
from .core.physics import CONTINUE, cartpole_step, physics_constants
from .core.random_stream import next_uniform

NEVER = -(2**62)  # the tick of a counter that was never set in this trial
TIE_EXACT, TIE_INDEX, TIE_RANDOM = (TIE_BREAKS.index(t) for t in ("exact", "index", "random"))


@numba.njit(cache=True)
def _segment_response(weights, neuron, segment, active):
    """(sum of ceil(w), sum of w) over the spiking inputs of one segment."""
    ceiled = 0.0
    exact = 0.0
    for v in range(active.shape[0]):
        w = weights[neuron, segment, active[v]]
        ceiled += math.ceil(w)
        exact += w
    return ceiled, exact


@numba.njit(cache=True)
def _beats(ceiled, exact, best_ceiled, best_exact, tie_break):
    """Does a later candidate beat the best so far? Earlier (lower index) wins a full tie."""
    if ceiled != best_ceiled:
        return ceiled > best_ceiled
    return tie_break == TIE_EXACT and exact > best_exact


@numba.njit(cache=True)
def _dendrite_winner(weights, neuron, active, tie_break, rng):
    n_segments = weights.shape[1]
    best, (best_ceiled, best_exact) = 0, _segment_response(weights, neuron, 0, active)
    n_tied = 1
    for s in range(1, n_segments):
        ceiled, exact = _segment_response(weights, neuron, s, active)
        if tie_break == TIE_RANDOM:
            if ceiled > best_ceiled:
                best, best_ceiled, n_tied = s, ceiled, 1
            elif ceiled == best_ceiled:
                n_tied += 1
        elif _beats(ceiled, exact, best_ceiled, best_exact, tie_break):
            best, best_ceiled, best_exact = s, ceiled, exact
    if tie_break == TIE_RANDOM and n_tied > 1:
        pick = int(next_uniform(rng) * n_tied)
        for s in range(n_segments):
            if _segment_response(weights, neuron, s, active)[0] == best_ceiled:
                if pick == 0:
                    return s
                pick -= 1
    return best


@numba.njit(cache=True)
def _infer(weights, active, tie_break, rng, out):
    """Write (winning neuron, dendrite winner of neuron 0, of neuron 1) into `out`."""
    s0 = _dendrite_winner(weights, 0, active, tie_break, rng)
    s1 = _dendrite_winner(weights, 1, active, tie_break, rng)
    c0, e0 = _segment_response(weights, 0, s0, active)
    c1, e1 = _segment_response(weights, 1, s1, active)
    if tie_break == TIE_RANDOM and c0 == c1:
        neuron = int(next_uniform(rng) * 2)
    else:
        neuron = 1 if _beats(c1, e1, c0, e0, tie_break) else 0
    out[0], out[1], out[2] = neuron, s0, s1


@numba.njit(cache=True)
def _fill_decisions(weights, offsets, radix, tie_break, rng, decisions):
    """Cache the network decision for every input pattern (mixed-radix index over variables)."""
    n_vars = offsets.shape[0]
    active = np.empty(n_vars, dtype=np.int64)
    for pattern in range(decisions.shape[0]):
        rest = pattern
        for v in range(n_vars - 1, -1, -1):
            active[v] = offsets[v] + rest % radix[v]
            rest //= radix[v]
        _infer(weights, active, tie_break, rng, decisions[pattern])


@numba.njit(cache=True)
def run_episode_kernel(weights, angles, constants, force, components, edges, offsets, max_steps,
                       sigma, omega, rho_plus, rho_minus, punish, w_max, tie_break, tag_both,
                       e_latched, counter_per_trial, learn, rng, steps_out, status_out):
    """One episode in place: `weights` end as the final weights, per-trial results in the outputs."""
    n_segments, n_inputs = weights.shape[1], weights.shape[2]
    n_vars = components.shape[0]
    radix = np.empty(n_vars, dtype=np.int64)
    for v in range(n_vars):
        radix[v] = (offsets[v + 1] if v + 1 < n_vars else n_inputs) - offsets[v]
    n_patterns = 1
    for v in range(n_vars):
        n_patterns *= radix[v]
    decisions = np.empty((n_patterns, 3), dtype=np.int64)
    use_cache = tie_break != TIE_RANDOM
    if use_cache:
        _fill_decisions(weights, offsets, radix, tie_break, rng, decisions)
    punish_tag = np.empty((2, n_segments, n_inputs), dtype=np.int64)
    reward_tag = np.empty((2, n_segments), dtype=np.int64)
    eligible = np.zeros((2, n_segments, n_inputs), dtype=np.uint8)
    state = np.empty(4)
    active = np.empty(n_vars, dtype=np.int64)
    decision = np.empty(3, dtype=np.int64)
    successes = 0
    for trial in range(angles.shape[0]):
        punish_tag[:] = NEVER
        reward_tag[:] = NEVER
        eligible[:] = 0
        if counter_per_trial:
            successes = 0
        x, x_dot, theta, theta_dot = 0.0, 0.0, angles[trial], 0.0
        t = 0
        status = CONTINUE
        while t < max_steps:
            state[0], state[1], state[2], state[3] = x, x_dot, theta, theta_dot
            encode_active(state, components, edges, offsets, active)
            if use_cache:
                pattern = 0
                for v in range(n_vars):
                    pattern = pattern * radix[v] + active[v] - offsets[v]
                decision[:] = decisions[pattern]
            else:
                _infer(weights, active, tie_break, rng, decision)
            neuron = decision[0]
            for n in range(2):
                if n == neuron or tag_both:
                    segment = decision[1 + n]
                    for v in range(n_vars):
                        punish_tag[n, segment, active[v]] = t
                    reward_tag[n, segment] = t
                    eligible[n, segment, :] = 0
                    for v in range(n_vars):
                        eligible[n, segment, active[v]] = 1
            x, x_dot, theta, theta_dot, status = cartpole_step(
                x, x_dot, theta, theta_dot, force if neuron == 1 else -force, constants)
            changed = False
            if status != CONTINUE:
                if learn:
                    for n in range(2):
                        for s in range(n_segments):
                            for i in range(n_inputs):
                                c = omega - (t - punish_tag[n, s, i])
                                if c > 0:
                                    weights[n, s, i] = min(max(
                                        weights[n, s, i] - punish * c / omega, 0.0), w_max)
                    changed = True
            else:
                successes += 1
                if successes == sigma:
                    successes = 0
                    if learn:
                        for n in range(2):
                            for s in range(n_segments):
                                c = sigma - (t - reward_tag[n, s])
                                if c > 0:
                                    for i in range(n_inputs):
                                        if e_latched:
                                            spiked = eligible[n, s, i] == 1
                                        else:
                                            spiked = False
                                            for v in range(n_vars):
                                                spiked = spiked or active[v] == i
                                        rate = rho_plus if spiked else -rho_minus
                                        weights[n, s, i] = min(max(
                                            weights[n, s, i] + rate * c / sigma, 0.0), w_max)
                        changed = True
            if changed and use_cache:
                _fill_decisions(weights, offsets, radix, tie_break, rng, decisions)
            if status != CONTINUE:
                break
            t += 1
        steps_out[trial] = t
        status_out[trial] = status


@numba.njit(parallel=True, cache=True)
def _run_many(weights, angles, constants, force, components, edges, offsets, max_steps, sigma,
              omega, rho_plus, rho_minus, punish, w_max, tie_break, tag_both, e_latched,
              counter_per_trial, learn, rng, steps_out, status_out):
    for k in numba.prange(weights.shape[0]):
        run_episode_kernel(weights[k], angles[k], constants, force, components, edges, offsets,
                           max_steps, sigma, omega, rho_plus, rho_minus, punish, w_max, tie_break,
                           tag_both, e_latched, counter_per_trial, learn, rng[k], steps_out[k],
                           status_out[k])


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
              offsets, p.max_steps, p.sigma, p.omega, p.rho_plus, p.rho_minus, p.punish,
              p.w_max, TIE_BREAKS.index(p.tie_break), p.tagging == "both_neurons",
              p.e_flag == "latched", p.success_counter == "per_trial", learn, rng, steps, status)
    wall = time.perf_counter() - start
    return BatchResult(seeds, all_angles, steps, status, all_weights, wall)


def evaluate_weights_batch(weights: np.ndarray, p: Params) -> BatchResult:
    """Fixed weights, one trial per grid angle (Figures 8 and 13), compiled."""
    return run_batch([0], p, weights=weights, angles=angle_grid(p), learn=False)
