"""Reinforcement-learning neurons (RLNs) and the three-factor learning rules, sections 2.2-2.3.

Two RLNs, neuron 0 drives -F and neuron 1 drives +F. Each has one dendrite of q segments; each
segment has one synapse per encoder input. This is the reference implementation: it keeps the
per-synapse state exactly as the paper's Figures 5 and 6 describe it, as explicit decay counters.

Inference (every tick):
    segment response = sum over spiking inputs of ceil(w)      (small-integer inference)
    dendrite WTA picks each neuron's best segment, network WTA picks the neuron (the action).
    Ties (all initial weights ceil to 5) are broken by the exact un-ceiled sums, then the lowest
    index (`tie_break="exact"`); "index" skips the exact sums, "random" picks among the tied.

Tagging (the action path): the winning segment of the winning neuron. Its spiking synapses get
the punishment decay counter c- = omega; the segment gets the reward counter c+ = sigma and each
of its synapses an e flag latched now (1 if its input spiked).

Update, after the environment step:
    punishment (failure):   w -= pi * c- / omega            for every synapse with c- > 0
    reward (every sigma-th success):
                            w += rho+ * c+ / sigma  if e = 1,  w -= rho- * c+ / sigma  if e = 0,
                            for every synapse of every segment with c+ > 0
    then every counter decays by one; weights are clipped to [0, w_max].
"""

from __future__ import annotations

import numpy as np

from .params import Params
from .random_stream import next_uniform

NONE, REWARD, PUNISH = 0, 1, 2
REWARD_KINDS = ("none", "reward", "punish")
ONE_HOT = {NONE: (0, 0), REWARD: (1, 0), PUNISH: (0, 1)}  # the paper's R code


class SuccessCounter:
    """Counts successful steps; signals a positive reward every sigma of them and a punishment on
    failure (the paper's 1-hot reward R)."""

    def __init__(self, params: Params):
        self.sigma = params.sigma
        self.per_trial = params.success_counter == "per_trial"
        self.count = 0

    def begin_trial(self) -> None:
        if self.per_trial:
            self.count = 0

    def outcome(self, failed: bool) -> int:
        """The reward kind for a step's outcome: PUNISH, REWARD or NONE."""
        if failed:
            return PUNISH
        self.count += 1
        if self.count == self.sigma:
            self.count = 0
            return REWARD
        return NONE


class RLNAgent:
    """Two RLNs with a network WTA: spikes in, action out; a reward kind in, weights updated."""

    def __init__(self, params: Params, weights: np.ndarray, seed: int = 0):
        shape = (2, params.n_segments, params.n_inputs)
        weights = np.asarray(weights, dtype=np.float64)
        if weights.shape != shape:
            raise ValueError(f"weights must have shape {shape}, got {weights.shape}")
        if not np.all((weights >= 0) & (weights <= params.w_max)):
            raise ValueError(f"weights must lie in [0, w_max={params.w_max:g}]")
        self.p = params
        self.weights = weights.copy()
        self.punish_counter = np.zeros(shape, dtype=np.int64)  # c- per synapse
        self.reward_counter = np.zeros(shape[:2], dtype=np.int64)  # c+ per segment
        self.eligible = np.zeros(shape, dtype=np.uint8)  # e flag per synapse
        self.last_spikes = np.zeros(shape[2], dtype=np.uint8)
        self.random_state = np.array([seed], dtype=np.uint64)  # only used by tie_break="random"

    # Everything that changes while the agent runs (its state), by attribute name.
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

    def begin_trial(self) -> None:
        """Counters and e flags restart with each trial; the weights carry over."""
        self.punish_counter[:] = 0
        self.reward_counter[:] = 0
        self.eligible[:] = 0

    def infer(self, spikes: np.ndarray) -> tuple[int, tuple[int, int]]:
        """(winning neuron, the dendrite winner of each neuron) for a spike vector."""
        ceiled = np.ceil(self.weights) @ spikes  # (2, q) integer-valued responses
        exact = self.weights @ spikes
        segments = (self._winner(ceiled[0], exact[0]), self._winner(ceiled[1], exact[1]))
        neuron = self._winner(ceiled[[0, 1], segments], exact[[0, 1], segments])
        return neuron, segments

    def _winner(self, ceiled: np.ndarray, exact: np.ndarray) -> int:
        tied = np.flatnonzero(ceiled == ceiled.max())
        if len(tied) == 1 or self.p.tie_break == "index":
            return int(tied[0])
        if self.p.tie_break == "random":
            with np.errstate(over="ignore"):  # the stream wraps around by design
                return int(tied[int(next_uniform(self.random_state) * len(tied))])
        return int(tied[np.argmax(exact[tied])])  # argmax keeps the lowest index among equals

    def act(self, spikes: np.ndarray) -> tuple[int, int]:
        """Infer and tag the action path; returns (action = winning neuron, 0 = -F and 1 = +F,
        its winning segment)."""
        spikes = np.asarray(spikes, dtype=np.uint8)
        neuron, segments = self.infer(spikes)
        self.last_spikes = spikes
        self._tag(neuron, segments[neuron], spikes)
        if self.p.tagging == "both_neurons":
            self._tag(1 - neuron, segments[1 - neuron], spikes)
        return neuron, segments[neuron]

    def _tag(self, neuron: int, segment: int, spikes: np.ndarray) -> None:
        self.punish_counter[neuron, segment, spikes == 1] = self.p.omega
        self.reward_counter[neuron, segment] = self.p.sigma
        self.eligible[neuron, segment] = spikes

    def learn(self, kind: int) -> None:
        """Apply a reward kind (NONE, REWARD, PUNISH), then decay every counter by one."""
        p = self.p
        if kind == PUNISH:
            tagged = self.punish_counter > 0
            self.weights[tagged] -= p.punish * self.punish_counter[tagged] / p.omega
        elif kind == REWARD:
            tagged = self.reward_counter > 0  # segments on the path within sigma steps
            eligible = (self.eligible if p.e_flag == "latched"
                        else np.broadcast_to(self.last_spikes, self.eligible.shape))
            rate = np.where(eligible[tagged] == 1, p.rho_plus, -p.rho_minus)
            self.weights[tagged] += rate * self.reward_counter[tagged][:, None] / p.sigma
        if kind != NONE:
            np.clip(self.weights, 0.0, p.w_max, out=self.weights)
        np.maximum(self.punish_counter - 1, 0, out=self.punish_counter)
        np.maximum(self.reward_counter - 1, 0, out=self.reward_counter)
