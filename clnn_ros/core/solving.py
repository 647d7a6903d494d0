"""CartPole-v1 as the RL field judges an agent: from its training episodes' returns (not a
separate evaluation), it has solved the task at the first episode whose last 100 returns average
475 or more; what is compared is how many episodes and environment steps that took. One
judge for every agent: the RLN agent's runs, the field's agents (clnn_ros.baselines), the
goals' study."""

from __future__ import annotations

import numpy as np

SOLVED_MEAN = 475  # CartPole-v1's reward threshold
WINDOW = 100         # episodes averaged


def solved_episode(returns, threshold: float = SOLVED_MEAN) -> int | None:
    """The number of episodes (1-based) after which the last WINDOW average `threshold` (the
    task's; CartPole-v1's SOLVED_MEAN) or more; None if that never happened."""
    returns = np.asarray(returns, dtype=np.float64)
    if len(returns) < WINDOW:
        return None
    # Integer returns: the window sums are exact, and so is the comparison.
    sums = np.convolve(returns, np.ones(WINDOW), "valid")
    hits = np.flatnonzero(sums >= threshold * WINDOW)
    return int(hits[0]) + WINDOW if len(hits) else None


def steps_to_solve(returns) -> int | None:
    """The environment steps taken up to and including the solving episode (None: unsolved)."""
    episode = solved_episode(returns)
    return None if episode is None else int(np.sum(np.asarray(returns)[:episode]))


def solving_summary(all_returns) -> dict:
    """Over seeds (one row of returns each): how many solved, and the quartiles of the episodes
    and environment steps it took those that did."""
    episodes = [e for e in (solved_episode(r) for r in all_returns) if e is not None]
    steps = [s for s in (steps_to_solve(r) for r in all_returns) if s is not None]
    quartiles = (lambda v: tuple(float(q) for q in np.percentile(v, (25, 50, 75)))
                 if v else None)
    return dict(seeds=len(all_returns), solved=len(episodes), episodes=quartiles(episodes),
                steps=quartiles(steps))
