"""A play-test in gymnasium itself: the final weights of a `learn` run, frozen (no learning, no
exploration), play gymnasium.make("CartPole-v1") as it is: its own random start of all four
state variables, its 500-step truncation, its return (1 a step).

Episode k of learn seed s starts from env.reset(seed=RESET_STRIDE * s + seed_offset + k): each
(seed, episode) its own start, the same on every run; --seed-offset N plays starts that
offset 0 with N episodes did not (a held-out set).

Frozen weights give each input pattern a fixed action, so with a deterministic tie_break the
core's inference runs once per pattern and seed, and the episodes play by lookup; tie_break
"random" draws from the agent's random stream, so then it runs on every step.

Neuron 0 pushes with -F, neuron 1 with +F (core.physics.CartPole.step); gymnasium's action 1
pushes with +force_mag and 0 with -force_mag (cartpole.py: force = force_mag if action == 1
else -force_mag): the winning neuron is gymnasium's action.
"""

from __future__ import annotations

import itertools
import json
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path

import gymnasium
import numpy as np

from ..core.encoder import Encoder
from ..core.physics import GYM_PHYSICS
from ..core.params import Params
from ..core.agent import RLNAgent
from .common import progress, write_csv

GYM_ID = "CartPole-v1"
FROZEN_OFF = ("explore",)  # Params options that learn or explore: 0 (off) while playing
RESET_STRIDE = 1_000_000  # reset seeds per learn seed: seed_offset + episodes must not exceed it


@dataclass
class LearnOutput:
    name: str  # the run's file tag, e.g. "1sv"
    seeds: np.ndarray
    final_weights: np.ndarray  # (seeds, 2, segments, inputs)
    params: Params


def load_learn_output(folder: Path, run: str | None) -> LearnOutput:
    """The final_weights_<run>.npz that `learn --out folder` wrote; `run` may be left out when
    there is one. ValueError with one line for anything else."""
    if not folder.is_dir():
        raise ValueError(f"{folder}: no such folder (give the --out of clnn-reproduce learn)")
    runs = sorted(path.name.removeprefix("final_weights_").removesuffix(".npz")
                  for path in folder.glob("final_weights_*.npz"))
    if not runs:
        raise ValueError(f"{folder} holds no final_weights_*.npz (clnn-reproduce learn --out "
                         f"{folder} writes one)")
    if run is None:
        if len(runs) > 1:
            raise ValueError(f"{folder} holds several runs ({', '.join(runs)}): choose one with "
                             f"--run")
        run = runs[0]
    elif run not in runs:
        raise ValueError(f"{folder} holds no run {run!r}; it holds {', '.join(runs)}")
    path = folder / f"final_weights_{run}.npz"
    try:
        with np.load(path, allow_pickle=False) as data:
            return LearnOutput(run, data["seeds"], data["final_weights"],
                               Params().replace(**json.loads(str(data["params"]))))
    except (ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile) as error:
        raise ValueError(f"{path} is not an output of clnn-reproduce learn ({error})") from None


def frozen(p: Params) -> Params:
    return p.replace(**{name: 0 for name in FROZEN_OFF})


def reset_seed(learn_seed: int, episode: int, seed_offset: int) -> int:
    return RESET_STRIDE * int(learn_seed) + seed_offset + episode


class FrozenPolicy:
    """The action of one seed's frozen weights for a gymnasium observation."""

    def __init__(self, p: Params, weights: np.ndarray, seed: int):
        self.agent = RLNAgent(p, weights, seed=seed)
        self.encoder = Encoder.from_params(p)
        self.actions = None if p.tie_break == "random" else self._action_per_pattern()

    def _action_per_pattern(self) -> dict[tuple[int, ...], int]:
        """The action for every input pattern (one spiking input per encoded variable)."""
        _, _, offsets = self.encoder.arrays
        inputs = [range(offset, offset + len(edges) + 1)
                  for offset, edges in zip(offsets.tolist(), self.encoder.edges)]
        actions = {}
        for active in itertools.product(*inputs):
            spikes = np.zeros(self.encoder.n_inputs, dtype=np.uint8)
            spikes[list(active)] = 1
            actions[active] = int(self.agent.infer(spikes)[0])
        return actions

    def action(self, observation) -> int:
        """Gymnasium's observation (x, x_dot, theta rad, theta_dot rad/s) in the core's units
        (degrees for the pole), encoded, inferred."""
        x, x_dot, theta, theta_dot = (float(v) for v in observation)
        state = (x, x_dot, math.degrees(theta), math.degrees(theta_dot))
        if self.actions is None:
            return int(self.agent.infer(self.encoder.spikes(state))[0])
        return self.actions[tuple(self.encoder.active(state).tolist())]


def play(policy: FrozenPolicy, env, seed: int) -> int:
    """One episode from env.reset(seed=seed) to termination or truncation: its return."""
    observation, _ = env.reset(seed=seed)
    total = 0.0
    while True:
        observation, reward, terminated, truncated, _ = env.step(policy.action(observation))
        total += reward
        if terminated or truncated:
            return int(total)


def gym_eval(learn: LearnOutput, episodes: int, seed_offset: int) -> np.ndarray:
    """The returns, (seeds, episodes), of each seed's frozen weights in gymnasium's CartPole-v1."""
    if episodes < 1:
        raise ValueError(f"--episodes must be at least 1, got {episodes}")
    if not 0 <= seed_offset <= RESET_STRIDE - episodes:
        raise ValueError(f"--seed-offset must be from 0 to {RESET_STRIDE} - episodes "
                         f"({RESET_STRIDE - episodes}), got {seed_offset}")
    p = frozen(learn.params)
    returns = np.zeros((len(learn.seeds), episodes), dtype=np.int64)
    with gymnasium.make(GYM_ID) as env:
        for k, seed in enumerate(progress(learn.seeds.tolist(), "gym-eval")):
            policy = FrozenPolicy(p, learn.final_weights[k], seed)
            for episode in range(episodes):
                returns[k, episode] = play(policy, env, reset_seed(seed, episode, seed_offset))
    return returns


def write_gym_eval(learn: LearnOutput, returns: np.ndarray, out: Path) -> Path:
    rows = ([seed, episode, int(r)] for seed, row in zip(learn.seeds.tolist(), returns)
            for episode, r in enumerate(row))
    return write_csv(out / "gym_eval.csv", ["seed", "episode", "return"], rows)


def print_gym_eval(learn: LearnOutput, returns: np.ndarray) -> None:
    spec = gymnasium.spec(GYM_ID)
    other = [f"{name}={getattr(learn.params, name)}" for name, value in GYM_PHYSICS.items()
             if getattr(learn.params, name) != value]
    if other:
        print(f"note: {learn.name} learned with other physics than {GYM_ID}'s: "
              + ", ".join(other))
    print(f"{learn.name}: {len(learn.seeds)} seeds x {returns.shape[1]} episodes of {GYM_ID}, "
          f"frozen weights")
    print(f"{'seed':>6s} {'mean return':>12s} {'min':>5s} {f'at {spec.max_episode_steps}':>7s}")
    for seed, row in zip(learn.seeds.tolist(), returns):
        print(f"{seed:6d} {row.mean():12.1f} {row.min():5d} "
              f"{int((row == spec.max_episode_steps).sum()):7d}")
    means = returns.mean(axis=1)
    print(f"overall mean return {returns.mean():.1f}; seeds averaging >= "
          f"{spec.reward_threshold:g} (gymnasium's 'solved'): "
          f"{int((means >= spec.reward_threshold).sum())} of {len(means)}")
