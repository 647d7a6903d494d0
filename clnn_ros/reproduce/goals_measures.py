"""What `clnn-reproduce goals` measures: a configuration's episodes (Outcome) with its measures
and its ranks, the Figure 12 table set beside a learned one, and the whole study (Study)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.optimal import optimal_weights
from ..core.params import Params
from ..core.episode import returns
from ..core.solving import solved_episode
from .common import stuck
from .goals_settings import CONVERGED, GYM_SOLVED, GYM_TRUNCATION, LAST_TRIALS
from .gym_eval import FrozenPolicy


@dataclass
class Outcome:
    """One configuration's episodes: per-trial steps and ends, final weights, and (Gymnasium's
    world) the final weights' frozen play in gymnasium itself."""
    world: str
    label: str
    params: Params
    seeds: np.ndarray
    steps: np.ndarray  # (seeds, trials)
    end_status: np.ndarray
    final_weights: np.ndarray
    play: np.ndarray | None = None  # (seeds, episodes) returns in CartPole-v1

    @property
    def last_means(self) -> np.ndarray:
        return self.steps[:, -LAST_TRIALS:].mean(axis=1)

    @property
    def converged(self) -> float:
        return float(np.mean(self.last_means >= CONVERGED))

    @property
    def play_solved(self) -> float:
        """The share of seeds whose frozen play averages at least 475."""
        return float(np.mean(self.play.mean(axis=1) >= GYM_SOLVED))

    def gym_returns(self) -> np.ndarray:
        """Each trial as CartPole-v1 would count it: a step's reward 1, the failing step's too,
        truncated at 500."""
        return np.minimum(returns(self.steps, self.end_status), GYM_TRUNCATION)

    def solved_at(self) -> np.ndarray:
        """Per seed, the trial (1-based) at which the running mean of the last 100 returns first
        reaches 475 (core.solving); 0 where it never does."""
        return np.array([solved_episode(row) or 0 for row in self.gym_returns()], dtype=np.int64)

    def rolling_converged(self, threshold: float) -> np.ndarray:
        """Per trial, the share of seeds whose last 64 trials average at least `threshold`."""
        sums = np.cumsum(self.steps, axis=1)
        rolling = (sums[:, LAST_TRIALS - 1:] - np.pad(sums, ((0, 0), (1, 0)))[:, :-LAST_TRIALS]
                   ) / LAST_TRIALS
        return np.mean(rolling >= threshold, axis=0)


def rank(outcome: Outcome) -> tuple:
    """Better first: more seeds converged, fewer stuck, a higher mean."""
    means = outcome.steps.mean(axis=1)
    return (-outcome.converged, stuck(means), -means.mean())


def play_rank(outcome: Outcome) -> tuple:
    """Better first: more seeds whose frozen play averages 475, a higher mean return."""
    return (-outcome.play_solved, -outcome.play.mean())


def fig12_params(o: Outcome) -> Params:
    """o's parameters with Figure 12's segment count (its weights' shape)."""
    return o.params.replace(segments=optimal_weights(2).shape[1])


def fig12_cells(o: Outcome) -> dict:
    """Figure 12's action for every input pattern of o's encoding."""
    return FrozenPolicy(fig12_params(o), optimal_weights(2), 0).actions


@dataclass
class HandMade:
    label: str
    grid_mean: float  # over the 32 start angles of the protocol
    play: np.ndarray  # (episodes,) returns in CartPole-v1


@dataclass
class Study:
    candidates: list[Outcome]  # on the selection seeds
    grid: list[Outcome]  # on the selection seeds
    reported: dict[str, list[Outcome]]  # per world: Table 2, preset, best found, best rerand.
    hand_made: list[HandMade]
    play_angles: np.ndarray  # (report seeds, episodes) gymnasium's start angles, deg
    fig7_optimum: float  # paper physics, 1 SV: the Figure 7 weights' mean over the 32 angles
    kept_fig12: float  # paper 2 SV: mean steps of episodes that learn from the Figure 12 weights
    acts_as_1sv: float  # paper 2 SV: share of learned tables that play as the 1-SV optimum
    cells_from_fig12: float  # paper 2 SV: input patterns acted on unlike Figure 12, mean
    report_spec: str
    select_spec: str
