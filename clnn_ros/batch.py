"""Batch engine: many episodes (seeds) at once, compiled with numba.

It runs the core's own code, compiled: the physics, the encoder and every part of the learning
rule (inference, tagging, punishment, reward, counter decay, the success counter: the
`jitable` functions of clnn_ros.core.rln). What is its own is only the episode loop
and one shortcut: the network's decision for each input pattern is cached, and made again only
when the pattern comes back after a change of the weights (a punishment or a reward), except
with `tie_break="random"`, which draws on every tie.

How it spends its time (measured, docs/benchmark_core.md): a tick waits mostly on its physics
step, a chain of dependent operations through libm's sin and cos. So each thread runs two
seeds whose ticks take turns part by part (two lanes: both decide, both step, both learn), the
one lane's step running while the other's waits; the rare work (a reward or punishment, a
trial's end) is done outside the tick loop. Seeds take very different times (a seed stuck in a
local optimum fails in few steps), so the threads take them from a shared queue, one at a time,
and end together.

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
from numba.core import types
from numba.extending import intrinsic, register_jitable

from .core import encoder, jitable, params, physics, random_stream, rln
from .core import rule as rule_values
from .core.agent import Kernels
from .core.encoder import Encoder, encode_active
from .core.episode import angle_grid, first_angle, seed_setup, trial_starts
from .core.params import CARTPOLE, ParamError, Params
from .core.physics import (CONTINUE, in_degrees, physics_constants, physics_step, start_in_units,
                           state_in_radians, trial_start_state)
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

# The rule's costly functions compiled for an agent that ticks in Python (core.agent.Kernels):
# a task's network of thousands of synapses, stepped by its own simulator (core.task_episode).
COMPILED_KERNELS = Kernels(*(numba.njit(cache=True)(function)
                             for function in (rln.infer, rln.update, rln.rerandomize)))


# ---- one lane: one seed's episode, tick by tick ------------------------------------------------
# A lane is a tuple of arrays: (weights, starts, steps_out, status_out, random_state) of its seed
# and its own scratch (decisions, punish_tagged_at, reward_tagged_at, eligible, active,
# responses). Its clock is a tuple of scalars: (x, x_dot, theta, theta_dot, t, trial, successes,
# now), the state in the physics' own units (core.physics: degrees, or radians for gymnasium).
# The setting, shared by all lanes: (constants, force, components, edges, offsets, radix,
# max_steps, released, rule, learn, radians).

@register_jitable
def _start_trial(lane, clock, setting):
    """Trial clock[5] of the lane's seed begins (the core's begin_trial and reset)."""
    weights, starts, _, _, rng, decisions, punish_tagged_at, reward_tagged_at, eligible, _, _ = lane
    constants, _, _, _, _, _, _, released, rule, learn, radians = setting
    _, _, _, _, _, trial, successes, now = clock
    restart_counters(punish_tagged_at, reward_tagged_at, eligible, rule)
    if learn and rerandomize(weights, trial, rule, rng):
        decisions[:, 0] = STALE
    successes = trial_start_count(successes, rule)
    start = starts[trial]
    x, x_dot, theta, theta_dot = trial_start_state(start[0], start[1], start[2], start[3],
                                                   released, constants, radians)
    return x, x_dot, theta, theta_dot, np.int64(0), trial, successes, now


@register_jitable
def _start_seed(lane, setting):
    """The clock of a seed's first trial; the lane's scratch as at the start of an episode."""
    decisions, punish_tagged_at, reward_tagged_at, eligible = lane[5:9]
    decisions[:, 0] = STALE
    punish_tagged_at[:] = NEVER
    reward_tagged_at[:] = NEVER
    eligible[:] = 0
    zero = np.int64(0)  # not the literal 0: the clock's type is that of a running lane's
    return _start_trial(lane, (0.0, 0.0, 0.0, 0.0, zero, zero, zero, zero), setting)


@register_jitable(forceinline=True)
def _act(lane, clock, setting):
    """The first part of a tick (the core's RLNAgent.infer and explore): the spiking inputs of
    the lane's state and the acting neuron. Returns (neuron, the input pattern's number)."""
    weights, rng, decisions, active, responses = lane[0], lane[4], lane[5], lane[9], lane[10]
    _, _, components, edges, offsets, radix, _, _, rule, _, radians = setting
    x, x_dot, theta, theta_dot = clock[:4]
    encode_active(in_degrees(x, x_dot, theta, theta_dot, radians), components, edges, offsets,
                  active)
    pattern = 0  # mixed-radix number of the spiking inputs
    for v in range(active.shape[0]):
        pattern = pattern * radix[v] + active[v] - offsets[v]
    # The decision for an input pattern depends on the weights only (but for random ties, which
    # draw anew on every tie): it is cached per pattern, and made again when the pattern comes
    # back after a change of the weights.
    if decisions[pattern, 0] == STALE or rule.tie_break == TIE_RANDOM:
        decisions[pattern, 0] = infer(weights, active, rule, rng, responses, decisions[pattern, 1:])
    return explore(decisions[pattern, 0], weights.shape[0], rule, rng), pattern


@register_jitable(forceinline=True)
def _step(clock, neuron, setting):
    """The physics step of a tick: (x, x_dot, theta, theta_dot, status)."""
    constants, force, radians = setting[0], setting[1], setting[10]
    x, x_dot, theta, theta_dot = clock[:4]
    return physics_step(x, x_dot, theta, theta_dot, force if neuron == 1 else -force, constants,
                        radians)


@register_jitable(forceinline=True)
def _learn(lane, clock, setting, neuron, pattern, stepped):
    """The rest of a tick, after its physics step `stepped`: the core's RLNAgent.act's tagging,
    the success counter, and RLNAgent.learn when there is no reward (the counters decay: the
    clock advances). Returns (clock, reward kind, status); with a reward kind other than NONE,
    or at the trial's end, the lane is to be settled (_settle) before its next tick."""
    (weights, _, _, _, _, decisions, punish_tagged_at, reward_tagged_at, eligible, active,
     _) = lane
    rule, learn = setting[8], setting[9]
    t, trial, successes, now = clock[4:]
    x, x_dot, theta, theta_dot, status = stepped
    # Tagged after the step (it reads nothing the step writes): the step's long chain of
    # dependent operations, which the next tick waits for, starts the earliest.
    tag_action_path(punish_tagged_at, reward_tagged_at, eligible, neuron,
                    (decisions[pattern, 1], decisions[pattern, 2]), active, now, rule)  # 2 neurons
    kind, successes = outcome(successes, status != CONTINUE, rule)
    if learn and kind == NONE:
        now = update(kind, weights, punish_tagged_at, reward_tagged_at, eligible, active, now,
                     rule)
    if status == CONTINUE:
        t += 1
    return (x, x_dot, theta, theta_dot, t, trial, successes, now), kind, status


@register_jitable
def _settle(lane, clock, kind, status, setting):
    """The rest of the tick that _learn left: RLNAgent.learn with a reward kind other than NONE;
    at the end of a trial its results are written and the next trial begins. Returns (clock,
    whether the seed is done)."""
    (weights, starts, steps_out, status_out, _, decisions, punish_tagged_at, reward_tagged_at,
     eligible, active, _) = lane
    max_steps, rule, learn = setting[6], setting[8], setting[9]
    x, x_dot, theta, theta_dot, t, trial, successes, now = clock
    if learn and kind != NONE:
        now = update(kind, weights, punish_tagged_at, reward_tagged_at, eligible, active, now,
                     rule)
        decisions[:, 0] = STALE
    clock = (x, x_dot, theta, theta_dot, t, trial, successes, now)
    if status == CONTINUE and t < max_steps:
        return clock, False
    steps_out[trial] = t
    status_out[trial] = status
    if trial + 1 == starts.shape[0]:
        return clock, True
    return _start_trial(lane, (x, x_dot, theta, theta_dot, t, trial + 1, successes, now),
                        setting), False


# error_model="numpy": no test for a division by zero (a branch at each division); none can
# happen (the physics divides by the total mass and by (4/3) M l - m l cos^2 > 0, the rule by
# sigma and omega >= 1: Params validates them), so the results are the same. With no branch
# between them, LLVM makes the physics' sin and cos one call of libm's sincos: the same bits
# for the pole's angles (|theta| <= 12 deg; tests/test_batch_lanes.py checks the pair).
@numba.njit(cache=True, _nrt=False, error_model="numpy")
def _tick(lane_a, clock_a, lane_b, clock_b, setting, both):
    """Lane a ticks, and with `both` lane b too, until one of them is to be settled (a reward or
    a punishment, or a trial's end): returns (clock, reward kind, status) of a, then of b. The
    two lanes' ticks take turns part by part: a tick waits mostly on its physics step's chain of
    dependent operations, and the other lane's step, next to it, runs in that wait."""
    max_steps = setting[6]
    neuron_b, pattern_b, stepped_b = 0, 0, (0.0, 0.0, 0.0, 0.0, CONTINUE)
    kind_b, status_b = NONE, CONTINUE
    while True:
        neuron_a, pattern_a = _act(lane_a, clock_a, setting)
        if both:
            neuron_b, pattern_b = _act(lane_b, clock_b, setting)
        stepped_a = _step(clock_a, neuron_a, setting)
        if both:
            stepped_b = _step(clock_b, neuron_b, setting)
        clock_a, kind_a, status_a = _learn(lane_a, clock_a, setting, neuron_a, pattern_a,
                                           stepped_a)
        if both:
            clock_b, kind_b, status_b = _learn(lane_b, clock_b, setting, neuron_b, pattern_b,
                                               stepped_b)
        if kind_a != NONE or clock_a[4] >= max_steps or (
                both and (kind_b != NONE or clock_b[4] >= max_steps)):
            return clock_a, kind_a, status_a, clock_b, kind_b, status_b


@intrinsic
def _take_next(typingctx, counter):
    """counter[0] += 1, atomically; returns the value before (a shared work queue's next item)."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        return builder.atomic_rmw("add", array.data, context.get_constant(types.int64, 1),
                                  "seq_cst")
    return types.int64(counter), codegen


@register_jitable
def _lane(k, episodes, scratch):
    """The lane that runs seed k (row k of the episodes' arrays) in this scratch."""
    weights, starts, steps_out, status_out, rng = episodes
    decisions, punish_tagged_at, reward_tagged_at, eligible, active, responses = scratch
    return (weights[k], starts[k], steps_out[k], status_out[k], rng[k], decisions,
            punish_tagged_at, reward_tagged_at, eligible, active, responses)


@numba.njit(cache=True)
def _scratch(n_patterns, n_neurons, n_segments, n_inputs, n_vars):
    """A lane's own arrays: (decisions: per input pattern the acting neuron and each neuron's
    winning segment, punish_tagged_at, reward_tagged_at, eligible, active, responses)."""
    shape = (n_neurons, n_segments, n_inputs)
    return (np.empty((n_patterns, 1 + n_neurons), np.int64), np.empty(shape, np.int64),
            np.empty((n_neurons, n_segments), np.int64), np.empty(shape, np.uint8),
            np.empty(n_vars, np.int64), response_space(n_neurons, n_segments))


# No reference counting here and in _tick: it would cost more than a tick's own work. All the
# arrays they use are made by _run_many.
@numba.njit(cache=True, _nrt=False)
def _work(taken, episodes, setting, scratch_a, scratch_b):
    """One thread's work: seeds from the shared queue `taken`, two at a time (lanes a and b, each
    with its scratch), until the queue is empty."""
    n_seeds = episodes[0].shape[0]
    k_a, k_b = _take_next(taken), _take_next(taken)
    clock_a = clock_b = (0.0, 0.0, 0.0, 0.0, np.int64(0), np.int64(0), np.int64(0), np.int64(0))
    if k_a < n_seeds:
        clock_a = _start_seed(_lane(k_a, episodes, scratch_a), setting)
    if k_b < n_seeds:
        clock_b = _start_seed(_lane(k_b, episodes, scratch_b), setting)
    while k_a < n_seeds:
        both = k_b < n_seeds
        lane_a = _lane(k_a, episodes, scratch_a)
        lane_b = _lane(k_b if both else k_a, episodes, scratch_b)
        clock_a, kind_a, status_a, clock_b, kind_b, status_b = _tick(
            lane_a, clock_a, lane_b, clock_b, setting, both)
        clock_a, done_a = _settle(lane_a, clock_a, kind_a, status_a, setting)
        if done_a:
            k_a = _take_next(taken)
            if k_a < n_seeds:
                clock_a = _start_seed(_lane(k_a, episodes, scratch_a), setting)
        if both:
            clock_b, done_b = _settle(lane_b, clock_b, kind_b, status_b, setting)
            if done_b:
                k_b = _take_next(taken)
                if k_b < n_seeds:
                    clock_b = _start_seed(_lane(k_b, episodes, scratch_b), setting)
        if k_a >= n_seeds:  # lane a idle: b, if it still runs, goes on alone as lane a
            k_a, k_b, clock_a, clock_b = k_b, k_a, clock_b, clock_a
            scratch_a, scratch_b = scratch_b, scratch_a


@numba.njit(parallel=True, cache=True)
def _run_many(weights, starts, constants, force, components, edges, offsets, max_steps,
              released, rule, learn, radians, rng, steps_out, status_out, n_threads):
    """Every seed's episode in place: `weights` end as the final weights, per-trial results in
    the outputs."""
    n_seeds, n_neurons, n_segments, n_inputs = weights.shape
    if n_seeds == 0 or starts.shape[1] == 0:
        return
    n_vars = components.shape[0]
    radix = np.empty(n_vars, dtype=np.int64)  # inputs per variable
    for v in range(n_vars):
        radix[v] = (offsets[v + 1] if v + 1 < n_vars else n_inputs) - offsets[v]
    n_patterns = 1
    for v in range(n_vars):
        n_patterns *= radix[v]
    # Seeds run for very different times (a seed stuck in a local optimum fails in few steps):
    # each thread takes the next seed not yet taken whenever one of its lanes is free, so that
    # the threads end together, whatever the seeds' lengths and their order.
    taken = np.zeros(1, np.int64)
    for _ in numba.prange(min(n_threads, n_seeds)):
        _work(taken, (weights, starts, steps_out, status_out, rng),
              (constants, force, components, edges, offsets, radix, max_steps, released, rule,
               learn, radians),
              _scratch(n_patterns, n_neurons, n_segments, n_inputs, n_vars),
              _scratch(n_patterns, n_neurons, n_segments, n_inputs, n_vars))


def drop_stale_cache(dispatchers, stamp_name: str, modules=()) -> None:
    """Numba's disk cache checks only the file of each cached function, not the core files whose
    functions are compiled into it (a documented limitation, numba/numba#1833): after a change
    to one of those, the cached engine would run the old rule. A digest of them (and of
    `modules`, other files compiled in) beside the cache, in `stamp_name`, drops the cache of
    `dispatchers` then (through their cache objects: numba has no public call)."""
    # params: the option indices (TIE_BREAKS) are compiled in as constants
    core = (rln, rule_values, physics, encoder, random_stream, params, jitable, *modules)
    core_sources = b"".join(Path(m.__file__).read_bytes() for m in core)
    digest = hashlib.sha256(core_sources).hexdigest()
    stamp = Path(dispatchers[0]._cache._cache_path) / stamp_name
    try:
        if stamp.exists() and stamp.read_text() == digest:
            return
        for dispatcher in dispatchers:
            dispatcher._cache.flush()
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest)
    except OSError:  # a read-only cache: numba then compiles anew in each process
        pass


drop_stale_cache((_run_many, _scratch, _work, _tick, *vars(COMPILED_KERNELS).values()),
                 "batch.core_sources.sha256")


@dataclass
class BatchResult:
    seeds: np.ndarray  # (S,)
    initial_angles: np.ndarray  # (S, trials) deg: each trial's first pole angle
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
    `weights` (2, q, n) and `angles` (trials,: the paper's starts at these angles) override every
    seed's own."""
    if p.task != CARTPOLE:
        raise ParamError(f"the cart-pole batch engine runs task {CARTPOLE!r}, not {p.task!r}")
    if _distributor is not None and weights is None and angles is None and learn:
        return _distributor(seeds, p)
    seeds = np.asarray(list(seeds), dtype=np.int64)
    radians = state_in_radians(p)
    all_weights = np.stack([seed_setup(int(s), p)[0] if weights is None else
                            np.asarray(weights, np.float64) for s in seeds]) \
        if len(seeds) else np.zeros((0, 2, p.n_segments, p.n_inputs))
    starts, angles_out = [], []
    for s in seeds:
        given, in_radians = trial_starts(int(s), p, angles)
        starts.append([start_in_units(start, in_radians, radians) for start in given])
        angles_out.append([first_angle(start, in_radians) for start in given])
    trials = p.trials if angles is None else len(angles)
    all_starts = np.array(starts, dtype=np.float64).reshape(len(seeds), trials, 4)
    initial_angles = np.array(angles_out, dtype=np.float64).reshape(len(seeds), trials)
    components, edges, offsets = Encoder.from_params(p).arrays
    rng = seeds.astype(np.uint64).reshape(-1, 1).copy()
    steps = np.zeros(initial_angles.shape, dtype=np.int64)
    status = np.zeros(initial_angles.shape, dtype=np.int64)
    start = time.perf_counter()
    _run_many(all_weights, all_starts, physics_constants(p), float(p.force), components, edges,
              offsets, p.max_steps, p.first_action == "no_force", Rule.from_params(p), learn,
              radians, rng, steps, status, numba.get_num_threads())
    wall = time.perf_counter() - start
    return BatchResult(seeds, initial_angles, steps, status, all_weights, wall)


def evaluate_weights_batch(weights: np.ndarray, p: Params) -> BatchResult:
    """Fixed weights, one trial per grid angle (Figures 8 and 13), compiled."""
    return run_batch([0], p, weights=weights, angles=angle_grid(p), learn=False)
