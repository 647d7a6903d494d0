"""The agent's state and the success counter as objects, tick by tick: they hold what the rule of
clnn_ros.core.rln reads and writes, and call its functions (the batch engine calls the same
functions on arrays of its own)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .params import Params
from .rln import (NEVER, NONE, REWARD, TIE_RANDOM, Rule, counter_value, explore, infer,
                  rerandomize, response_space, restart_counters, tag_action_path, task_outcome,
                  trial_start_count, update)

NO_INPUTS = np.zeros(0, dtype=np.int64)


class SuccessCounter:
    """Counts successful steps; signals a positive reward every sigma of them and a punishment on
    failure (the paper's 1-hot reward R; reward_mapping="goal" or "shaped":
    core.rln.task_outcome)."""

    def __init__(self, params: Params):
        self.rule = Rule.from_params(params)
        self.count = 0
        self.window = 0.0  # reward_mapping="shaped": the rewards' sum since the last signal

    def begin_trial(self) -> None:
        self.count = trial_start_count(self.count, self.rule)
        self.window = 0.0

    def outcome(self, terminated: bool, reward: float) -> int:
        """The reward kind for a step's outcome (whether it terminated the episode: the
        cart-pole's failure; the task's reward for it): PUNISH, REWARD or NONE."""
        kind, self.count, self.window = task_outcome(self.count, self.window, terminated,
                                                     float(reward), self.rule)
        return kind


@dataclass(frozen=True)
class Kernels:
    """The rule's functions whose work grows with the network (every synapse, every segment):
    the core's own, in Python (the nodes' few dozen synapses), or the same functions compiled
    by the batch engine (clnn_ros.batch.COMPILED_KERNELS: a task's thousands, the same results
    bit for bit)."""

    infer: Callable = infer
    update: Callable = update
    rerandomize: Callable = rerandomize


PYTHON_KERNELS = Kernels()


class RLNAgent:
    """One RLN per action (params.n_actions) with a network WTA: spikes in, action out; a reward
    kind in, weights updated."""

    def __init__(self, params: Params, weights: np.ndarray, seed: int = 0,
                 kernels: Kernels = PYTHON_KERNELS):
        shape = (params.n_actions, params.n_segments, params.n_inputs)
        weights = np.asarray(weights, dtype=np.float64)
        if weights.shape != shape:
            raise ValueError(f"weights must have shape {shape}, got {weights.shape}")
        if not np.all((weights >= 0) & (weights <= params.w_max)):
            raise ValueError(f"weights must lie in [0, w_max={params.w_max:g}]")
        self.p = params
        self.kernels = kernels
        self.rule = Rule.from_params(params)
        self.weights = weights
        self.tick = 0  # the clock of the decay counters
        self.punish_tagged_at = np.full(shape, NEVER, dtype=np.int64)  # c- per synapse
        self.reward_tagged_at = np.full(shape[:2], NEVER, dtype=np.int64)  # c+ per segment
        self.eligible = np.zeros(shape, dtype=np.uint8)  # e flag per synapse
        self.last_spikes = np.zeros(shape[2], dtype=np.uint8)
        self.random_state = np.array([seed], dtype=np.uint64)  # only used by tie_break="random"

    @property
    def weights(self) -> np.ndarray:
        """(K, q, n_inputs), read-only: the rule alone changes them, and the decisions cached
        for them stay true."""
        return self._read_only_weights

    @weights.setter
    def weights(self, values: np.ndarray) -> None:
        self._weights = np.array(values, dtype=np.float64)  # a copy the rule writes to
        self._read_only_weights = self._weights.view()
        self._read_only_weights.flags.writeable = False
        self._decisions = {}

    @property
    def punish_counter(self) -> np.ndarray:
        """c- per synapse, (K, q, n_inputs)."""
        return counter_value(self.punish_tagged_at, self.tick, self.rule.omega)

    @punish_counter.setter
    def punish_counter(self, values: np.ndarray) -> None:
        self.punish_tagged_at = self._tagged_at(values, self.rule.omega)

    @property
    def reward_counter(self) -> np.ndarray:
        """c+ per segment, (K, q)."""
        return counter_value(self.reward_tagged_at, self.tick, self.rule.sigma)

    @reward_counter.setter
    def reward_counter(self, values: np.ndarray) -> None:
        self.reward_tagged_at = self._tagged_at(values, self.rule.sigma)

    def _tagged_at(self, values: np.ndarray, window: int) -> np.ndarray:
        """The ticks at which counters of these values were set (counter_value inverted)."""
        return np.where(values > 0, self.tick - (window - values), NEVER).astype(np.int64)

    # Everything that changes while the agent runs (its state), by attribute name; the counters
    # as their values, as the paper has them.
    STATE = ("weights", "punish_counter", "reward_counter", "eligible", "last_spikes",
             "random_state")

    def state(self) -> dict[str, np.ndarray]:
        """Copies of the agent's whole state (what core.checkpoint saves)."""
        return {name: getattr(self, name).copy() for name in self.STATE}

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        """Take over a state from state(): each array must have its attribute's shape and dtype;
        ValueError otherwise."""
        values = {name: np.array(state[name]) for name in self.STATE}  # copies
        for name, value in values.items():  # all checked before any is taken over
            current = getattr(self, name)
            if value.shape != current.shape or value.dtype != current.dtype:
                raise ValueError(f"{name} must be {current.dtype} of shape {current.shape}, "
                                 f"got {value.dtype} of shape {value.shape}")
        for name, value in values.items():
            setattr(self, name, value)

    def begin_trial(self, trial: int, learn: bool = True) -> None:
        """Trial `trial` of the episode (0 = the first) begins: counters and e flags restart
        (unless decay_counters="carry"); the weights carry over, but for those a learning agent
        re-randomizes (rerandomize_every)."""
        restart_counters(self.punish_tagged_at, self.reward_tagged_at, self.eligible, self.rule)
        if learn:
            with np.errstate(over="ignore"):  # the random stream wraps around by design
                if self.kernels.rerandomize(self._weights, trial, self.rule, self.random_state):
                    self._decisions.clear()

    def infer(self, spikes: np.ndarray) -> tuple[int, tuple[int, ...]]:
        """(winning neuron, the dendrite winner of each neuron) for a spike vector."""
        neuron, segments = self._decide(np.flatnonzero(spikes))
        return neuron, tuple(int(s) for s in segments)

    def _decide(self, active: np.ndarray) -> tuple[int, np.ndarray]:
        """infer for the spiking inputs `active`. A decision depends on the weights alone (but
        for random ties, drawn on every tie): it is kept until the weights change."""
        key = active.tobytes()
        decision = self._decisions.get(key)
        if decision is None:
            with np.errstate(over="ignore"):  # tie_break="random": the stream wraps around
                segments = np.empty(self.p.n_actions, dtype=np.int64)
                neuron = self.kernels.infer(self._weights, active, self.rule, self.random_state,
                                            response_space(self.p.n_actions, self.p.n_segments),
                                            segments)
            decision = int(neuron), segments
            if self.rule.tie_break != TIE_RANDOM:
                self._decisions[key] = decision
        return decision

    def act(self, spikes: np.ndarray) -> tuple[int, int]:
        """Infer and tag the action path; returns (action = the acting neuron's index, e.g. 0 = -F
        and 1 = +F on the cart-pole, its winning segment)."""
        spikes = np.asarray(spikes, dtype=np.uint8)
        active = np.flatnonzero(spikes)
        neuron, segments = self._decide(active)
        with np.errstate(over="ignore"):  # the random stream wraps around by design
            neuron = explore(neuron, self.p.n_actions, self.rule, self.random_state)
        self.last_spikes = spikes
        tag_action_path(self.punish_tagged_at, self.reward_tagged_at, self.eligible, neuron,
                        segments, active, self.tick, self.rule)
        return neuron, int(segments[neuron])

    def learn(self, kind: int) -> None:
        """Apply a reward kind (NONE, REWARD, PUNISH), then decay every counter by one."""
        # only a reward with e_flag="live" reads the latest spikes
        last_active = np.flatnonzero(self.last_spikes) if kind == REWARD else NO_INPUTS
        self.tick = self.kernels.update(kind, self._weights, self.punish_tagged_at,
                                        self.reward_tagged_at, self.eligible, last_active,
                                        self.tick, self.rule)
        if kind != NONE:
            self._decisions.clear()
