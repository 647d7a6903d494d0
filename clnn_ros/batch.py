"""Batch engine: many episodes (seeds) at once, compiled with numba, one seed per thread.

It runs the core's own code, compiled: the physics, the encoder and every part of the learning
rule (inference, tagging, punishment, reward, counter decay, the success counter: the
`jitable` functions of clnn_ros.core.rln). What is its own is only the episode loop
and one shortcut: the network's decision for each input pattern is cached, and made again only
when the pattern comes back after a change of the weights (a punishment or a reward), except
with `tie_break="random"`, which draws on every tie.

tests/test_batch.py proves it equal to the reference core (clnn_ros.core) trial by trial and in
the final weights, bit for bit, for every option value.
"""

from __future__ import annotations

import hashlib
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
from numba.extending import register_jitable

from .core import encoder, jitable, params, physics, random_stream, rln
from .core.encoder import Encoder, encode_active
from .core.episode import angle_grid, seed_setup
from .core.params import Params
from .core.physics import CONTINUE, cartpole_step, physics_constants, trial_start_state
from .core.rln import (NEVER, NONE, TIE_RANDOM, Rule, explore, infer, outcome, rerandomize,
                       response_space, restart_counters, tag_action_path, trial_start_count,
                       update)

# The core's functions, compiled where the engine calls them (the core itself imports no numba).
for _function, _options in jitable.MARKED:
    if _options:
        register_jitable(**_options)(_function)
    else:
        register_jitable(_function)

STALE = -1  # a cached decision made before the weights last changed


@numba.njit(cache=True)
def run_episode_kernel(weights, angles, constants, force, components, edges, offsets, max_steps,
                       released, rule, learn, rng, steps_out, status_out):
    """One episode in place: `weights` end as the final weights, per-trial results in the outputs."""
    n_segments, n_inputs = weights.shape[1], weights.shape[2]
    n_vars = components.shape[0]
    radix = np.empty(n_vars, dtype=np.int64)  # inputs per variable
    for v in range(n_vars):
        radix[v] = (offsets[v + 1] if v + 1 < n_vars else n_inputs) - offsets[v]
    n_patterns = 1
    for v in range(n_vars):
        n_patterns *= radix[v]
    _run_trials(weights, angles, constants, force, components, edges, offsets, max_steps,
                released, rule, learn, rng, steps_out, status_out, radix,
                np.empty((n_patterns, 3), np.int64),
                np.full((2, n_segments, n_inputs), NEVER, np.int64),
                np.full((2, n_segments), NEVER, np.int64),
                np.zeros((2, n_segments, n_inputs), np.uint8), np.empty(n_vars, np.int64),
                response_space(n_segments))


# No reference counting in the tick loop: it would cost more than the tick's own work. All the
# arrays it uses are made by run_episode_kernel.
@numba.njit(cache=True, _nrt=False)
def _run_trials(weights, angles, constants, force, components, edges, offsets, max_steps,
                released, rule, learn, rng, steps_out, status_out, radix, decisions,
                punish_tagged_at, reward_tagged_at, eligible, active, responses):
    # The decision for an input pattern depends on the weights only (but for random ties, which
    # draw anew on every tie): it is cached per pattern, and made again when the pattern comes
    # back after a change of the weights.
    use_cache = rule.tie_break != TIE_RANDOM
    decisions[:, 0] = STALE
    now = 0  # the clock of the decay counters
    successes = 0
    for trial in range(angles.shape[0]):
        restart_counters(punish_tagged_at, reward_tagged_at, eligible, rule)
        if learn and rerandomize(weights, trial, rule, rng):
            decisions[:, 0] = STALE
        successes = trial_start_count(successes, rule)
        x, x_dot, theta, theta_dot = trial_start_state(angles[trial], released, constants)
        t = 0
        status = CONTINUE
        while t < max_steps:
            encode_active((x, x_dot, theta, theta_dot), components, edges, offsets, active)
            pattern = 0  # mixed-radix number of the spiking inputs
            for v in range(active.shape[0]):
                pattern = pattern * radix[v] + active[v] - offsets[v]
            if decisions[pattern, 0] == STALE or not use_cache:
                decisions[pattern] = infer(weights, active, rule, rng, responses)
            neuron, s0, s1 = decisions[pattern, 0], decisions[pattern, 1], decisions[pattern, 2]
            neuron = explore(neuron, rule, rng)
            tag_action_path(punish_tagged_at, reward_tagged_at, eligible, neuron, (s0, s1),
                            active, now, rule)
            x, x_dot, theta, theta_dot, status = cartpole_step(
                x, x_dot, theta, theta_dot, force if neuron == 1 else -force, constants)
            kind, successes = outcome(successes, status != CONTINUE, rule)
            if learn:
                now = update(kind, weights, punish_tagged_at, reward_tagged_at, eligible, active,
                             now, rule)
                if kind != NONE:
                    decisions[:, 0] = STALE
            if status != CONTINUE:
                break
            t += 1
        steps_out[trial] = t
        status_out[trial] = status


@numba.njit(parallel=True, cache=True)
def _run_many(weights, angles, constants, force, components, edges, offsets, max_steps,
              released, rule, learn, rng, steps_out, status_out):
    for k in numba.prange(weights.shape[0]):
        run_episode_kernel(weights[k], angles[k], constants, force, components, edges, offsets,
                           max_steps, released, rule, learn, rng[k], steps_out[k],
                           status_out[k])


def _drop_stale_cache() -> None:
    """Numba's disk cache checks only the file of each cached function, not the core files whose
    functions are compiled into it (a documented limitation, numba/numba#1833): after a change
    to one of those, the cached engine would run the old rule. A digest of them beside the
    cache drops it then (through the dispatchers' cache objects: numba has no public call)."""
    # params: the option indices (TIE_BREAKS) are compiled in as constants
    core_sources = b"".join(Path(m.__file__).read_bytes() for m in (rln, physics, encoder,
                                                                    random_stream, params,
                                                                    jitable))
    digest = hashlib.sha256(core_sources).hexdigest()
    stamp = Path(_run_many._cache._cache_path) / "batch.core_sources.sha256"
    try:
        if stamp.exists() and stamp.read_text() == digest:
            return
        for dispatcher in (_run_many, run_episode_kernel, _run_trials):
            dispatcher._cache.flush()
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest)
    except OSError:  # a read-only cache: numba then compiles anew in each process
        pass


_drop_stale_cache()


@dataclass
class BatchResult:
    seeds: np.ndarray  # (S,)
    initial_angles: np.ndarray  # (S, trials) deg
    steps: np.ndarray  # (S, trials) successful steps
    end_status: np.ndarray  # (S, trials)
    final_weights: np.ndarray  # (S, 2, q, n_inputs)
    wall_s: float


# Who runs the plain learning runs (each seed's own weights and angles) while `distributed` holds:
# a function (seeds, p) -> BatchResult that hands their seeds to other processes, e.g. a Ray
# cluster's (clnn_ros.reproduce.common.executed_by). Those processes run them here, unhanded.
_distributor = None


@contextmanager
def distributed(distributor):
    """Within: run_batch(seeds, p) is distributor(seeds, p); equal arrays, other processes."""
    global _distributor
    before, _distributor = _distributor, distributor
    try:
        yield
    finally:
        _distributor = before


def run_batch(seeds, p: Params, weights: np.ndarray | None = None, angles: np.ndarray | None = None,
              learn: bool = True) -> BatchResult:
    """Run one episode per seed (the core's seed protocol), in parallel over seeds.
    `weights` (2, q, n) and `angles` (trials,) override every seed's own."""
    if _distributor is not None and weights is None and angles is None and learn:
        return _distributor(seeds, p)
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
              offsets, p.max_steps, p.first_action == "no_force", Rule.from_params(p), learn, rng,
              steps, status)
    wall = time.perf_counter() - start
    return BatchResult(seeds, all_angles, steps, status, all_weights, wall)


def evaluate_weights_batch(weights: np.ndarray, p: Params) -> BatchResult:
    """Fixed weights, one trial per grid angle (Figures 8 and 13), compiled."""
    return run_batch([0], p, weights=weights, angles=angle_grid(p), learn=False)
