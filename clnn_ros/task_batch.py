"""The task batch engine: a whole episode of a task compiled, its step included, for the tasks
whose step is compiled (clnn_ros.tasks.compiled: Acrobot-v1, MountainCar-v0,
InvertedPendulum-v5).

It runs the core's own rule compiled (inference, exploring, tagging, the success counter's
outcome, punishment and reward: the `jitable` functions of clnn_ros.core.rln, as the cart-pole's
batch engine does) around the task's compiled step; what is its own is only the episode loop,
core.episode.play_trial's, and the cache of the network's decision per input pattern that the
core's agent keeps too (RLNAgent._decide). Each trial starts where Gymnasium's own reset puts it
(the tasks' steps draw on no random stream, so the starts do not depend on what the agent did).

tests/test_task_batch.py proves it equal to the core's task episode in Gymnasium's own
environment (core.task_episode.run_task_episode) trial by trial and in the final weights, bit
for bit, for the rule's options.
"""

from __future__ import annotations

import numba
import numpy as np

from .batch import STALE, drop_stale_cache
from .core.encoder import Encoder, encode_active
from .core.episode import STARTS_SEED, seed_setup
from .core.params import Params
from .core.rln import (NEVER, NONE, TIE_RANDOM, Rule, explore, infer, rerandomize,
                       response_space, restart_counters, tag_action_path, task_outcome,
                       trial_start_count, update)
from .core.task import Task
from .core.task_episode import TaskEpisodeResult
from .tasks import classic_control, compiled, mujoco_control
from .tasks.gymnasium_task import GymnasiumEnvironment, env_id

MAX_CACHED_PATTERNS = 1 << 16  # more input patterns than this: a decision is made every tick


@numba.njit(cache=True)
def _episode(task, sim, forces, weights, starts, n_values, components, edges, offsets,
             max_steps, truncation, rule, learn, rng, steps_out, returns_out, terminated_out):
    """One seed's episode in place (`weights` end as the final weights; per trial its steps,
    return and whether it terminated), from each trial's start state `starts[trial]`
    (tasks.compiled: the task's code, its simulation and its actions' forces)."""
    n_neurons, n_segments, n_inputs = weights.shape
    n_vars = components.shape[0]
    radix = np.empty(n_vars, dtype=np.int64)  # inputs per variable
    n_patterns = 1
    for v in range(n_vars):
        radix[v] = (offsets[v + 1] if v + 1 < n_vars else n_inputs) - offsets[v]
        n_patterns *= radix[v]
    cached = n_patterns <= MAX_CACHED_PATTERNS and rule.tie_break != TIE_RANDOM
    decisions = np.full((n_patterns if cached else 1, 1 + n_neurons), STALE, np.int64)
    punish_tagged_at = np.full(weights.shape, NEVER, np.int64)
    reward_tagged_at = np.full((n_neurons, n_segments), NEVER, np.int64)
    eligible = np.zeros(weights.shape, np.uint8)
    active = np.empty(n_vars, np.int64)
    responses = response_space(n_neurons, n_segments)
    state = np.empty(starts.shape[1])
    values = np.empty(n_values)
    now, successes = 0, 0
    for trial in range(starts.shape[0]):
        restart_counters(punish_tagged_at, reward_tagged_at, eligible, rule)
        if learn and rerandomize(weights, trial, rule, rng):
            decisions[:, 0] = STALE
        successes, window = trial_start_count(successes, rule), 0.0
        state[:] = starts[trial]
        compiled.begin(task, state, sim)
        compiled.observe(task, state, sim, values)
        steps, total, terminated = 0, 0.0, False
        while steps < max_steps:
            encode_active(values, components, edges, offsets, active)
            pattern = 0
            if cached:  # the pattern's mixed-radix number
                for v in range(n_vars):
                    pattern = pattern * radix[v] + active[v] - offsets[v]
            if decisions[pattern, 0] == STALE or not cached:
                decisions[pattern, 0] = infer(weights, active, rule, rng, responses,
                                              decisions[pattern, 1:])
            neuron = explore(decisions[pattern, 0], n_neurons, rule, rng)
            tag_action_path(punish_tagged_at, reward_tagged_at, eligible, neuron,
                            decisions[pattern, 1:], active, now, rule)
            reward, terminated = compiled.step(task, state, sim, forces, neuron)
            compiled.observe(task, state, sim, values)
            total += reward
            kind, successes, window = task_outcome(successes, window, terminated, reward,
                                                   rule)
            if learn:
                now = update(kind, weights, punish_tagged_at, reward_tagged_at, eligible, active,
                             now, rule)
                if kind != NONE:
                    decisions[:, 0] = STALE
            steps += 1
            if terminated or steps >= truncation:
                break
        steps_out[trial], returns_out[trial], terminated_out[trial] = steps, total, terminated


drop_stale_cache((_episode,), "task_batch.core_sources.sha256",
                 (compiled, classic_control, mujoco_control))


def compiles(task: Task) -> bool:
    """Whether the task's step is compiled (the engine runs it)."""
    return env_id(task.name) in compiled.COMPILED


def run_compiled_task_episode(seed: int, p: Params, task: Task, env: GymnasiumEnvironment,
                              learn: bool = True,
                              weights: np.ndarray | None = None) -> TaskEpisodeResult:
    """core.task_episode.run_task_episode(seed, p, task, env, learn, weights), compiled: the
    same result. `env` (gymnasium_task.make's, of a task that compiles) gives the trials'
    starts."""
    task.check(p)
    compiled_task = compiled.CompiledTask(task, env.env)
    starts = []
    for trial in range(p.trials):
        env.reset(STARTS_SEED + seed if trial == 0 else None)
        starts.append(compiled_task.start_state(env.env))
    weights = (seed_setup(seed, p)[0] if weights is None else weights).astype(np.float64)
    steps = np.zeros(p.trials, dtype=np.int64)
    returns = np.zeros(p.trials, dtype=np.float64)
    terminated = np.zeros(p.trials, dtype=bool)
    components, edges, offsets = Encoder.from_params(p, task.names, task.units).arrays
    _episode(compiled_task.code, compiled_task.sim, compiled_task.forces, weights,
             np.array(starts, dtype=np.float64).reshape(p.trials, -1), len(task.variables),
             components, edges, offsets, p.max_steps,
             task.max_steps if task.max_steps is not None else p.max_steps,
             Rule.from_params(p), learn, np.array([seed], dtype=np.uint64), steps, returns,
             terminated)
    return TaskEpisodeResult(seed, steps, returns, terminated, weights)
