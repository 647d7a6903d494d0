"""An episode of any task (core.task): `trials` episodes of the task, in Gymnasium's sense, in
which one network keeps learning.

The environment is anything with Gymnasium's two calls, its actions numbered 0..K-1 (one per
RLN): reset(seed) -> observation and step(action) -> (observation, reward, terminated,
truncated). Seed protocol: the initial weights are the seed's (core.episode.seed_setup, K
neurons); trial 0 of seed s resets with seed STARTS_SEED + s, every later trial with None (the
environment's own stream goes on), as CartPole-v1's protocol does (core.episode). The tick is
the cart-pole's (core.episode.play_trial, the one loop of both).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .agent import PYTHON_KERNELS, Kernels, RLNAgent, SuccessCounter
from .encoder import Encoder
from .episode import STARTS_SEED, play_trial, seed_setup
from .params import Params
from .task import Task


class TaskEnvironment(Protocol):
    def reset(self, seed: int | None) -> np.ndarray: ...

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool]: ...


@dataclass
class TaskEpisodeResult:
    seed: int
    steps: np.ndarray  # (trials,) environment steps of each trial, the last one included
    returns: np.ndarray  # (trials,) each trial's sum of rewards, as Gymnasium counts it
    terminated: np.ndarray  # (trials,) bool: the trial terminated (else truncated or capped)
    final_weights: np.ndarray  # (K, q, n_inputs)


def run_task_episode(seed: int, p: Params, task: Task, env: TaskEnvironment,
                     learn: bool = True, weights: np.ndarray | None = None,
                     kernels: Kernels = PYTHON_KERNELS) -> TaskEpisodeResult:
    """One episode of p.trials trials of `task` in `env` (p made for it: Task.params); `weights`
    override the seed's own; `kernels`: the rule's costly functions, the core's or compiled
    (clnn_ros.batch.COMPILED_KERNELS: the same results)."""
    task.check(p)
    weights = seed_setup(seed, p)[0] if weights is None else weights
    agent, counter = RLNAgent(p, weights, seed=seed, kernels=kernels), SuccessCounter(p)
    encoder = Encoder.from_params(p, task.names, task.units)
    steps = np.zeros(p.trials, dtype=np.int64)
    returns = np.zeros(p.trials, dtype=np.float64)
    terminated = np.zeros(p.trials, dtype=bool)
    for trial in range(p.trials):
        observation = env.reset(STARTS_SEED + seed if trial == 0 else None)
        steps[trial], returns[trial], terminated[trial] = play_trial(
            agent, counter, encoder, observation, env.step, p.max_steps, learn, trial)
    return TaskEpisodeResult(seed, steps, returns, terminated, agent.weights.copy())
