"""The ASE/ACE baseline (Barto, Sutton & Anderson 1983) on CartPole-v1: box decoding, the
elements' update order, truncation, the solved criterion, determinism, and that it learns."""

import itertools
import math

import gymnasium
import numpy as np
import pytest

from clnn_ros.baselines import ase_ace
from clnn_ros.baselines.ase_ace import N_BOXES, AseAce, AseAceParams, boxes, train
from clnn_ros.core.solving import solved_episode

BINS_PER_VARIABLE = (3, 3, 6, 3)  # x, x_dot, theta, theta_dot


def bins_of(observation) -> tuple[int, ...]:
    return tuple(int(b) for b in np.unravel_index(boxes(observation), BINS_PER_VARIABLE))


def test_centre_state_is_in_the_middle_bins_and_theta_zero_in_the_upper_one():
    assert bins_of((0.0, 0.0, 0.0, 0.0)) == (1, 1, 3, 1)


@pytest.mark.parametrize("variable, edges, to_observed", [
    (0, (-0.8, 0.8), lambda v: v),
    (1, (-0.5, 0.5), lambda v: v),
    (2, (-6.0, -1.0, 0.0, 1.0, 6.0), math.radians),
    (3, (-50.0, 50.0), math.radians),
])
def test_each_threshold_separates_two_bins(variable, edges, to_observed):
    for bin_below, edge in enumerate(edges):
        for value, expected_bin in ((edge - 1e-6, bin_below), (edge + 1e-6, bin_below + 1)):
            observation = [0.0, 0.0, 0.0, 0.0]
            observation[variable] = to_observed(value)
            assert bins_of(observation)[variable] == expected_bin, (variable, value)
    if variable < 2:  # no unit conversion: the threshold itself opens the upper bin
        for bin_below, edge in enumerate(edges):
            observation = [0.0, 0.0, 0.0, 0.0]
            observation[variable] = edge
            assert bins_of(observation)[variable] == bin_below + 1


def test_grid_of_interval_midpoints_reaches_all_162_boxes():
    grid = itertools.product((-1.6, 0.0, 1.6), (-1.0, 0.0, 1.0),
                             np.radians((-9.0, -3.5, -0.5, 0.5, 3.5, 9.0)),
                             np.radians((-100.0, 0.0, 100.0)))
    assert sorted(boxes(observation) for observation in grid) == list(range(N_BOXES))


def test_only_states_beyond_the_limits_decode_as_failure():
    limit_theta = 12 * 2 * math.pi / 360  # Gymnasium's own expression
    for x, theta in ((2.41, 0.0), (-2.41, 0.0), (0.0, math.radians(12.01)),
                     (0.0, -math.radians(12.01))):
        assert boxes((x, 0.0, theta, 0.0)) is None
    # Exactly at Gymnasium's limits (not terminated), as its float32 observation rounds them up.
    for x, theta in ((2.4, limit_theta), (-2.4, -limit_theta)):
        observation = np.array((x, 3.0, theta, -3.0), dtype=np.float32)
        assert bins_of(observation) == (2 if x > 0 else 0, 2, 5 if x > 0 else 0, 0)


def test_weights_move_in_the_papers_synchronous_order():
    """r_hat(t+1) is computed when x(t+1) arrives but reaches the weights after y(t+1)."""
    agent = AseAce(AseAceParams(), np.random.default_rng(0))
    agent.critic_weights[7] = -1.0
    y0 = 2 * agent.act(3) - 1
    agent.learn(7, failed=False, truncated=False)  # r_hat = 0.95 * -1 - 0
    assert not agent.action_weights.any()
    agent.act(7)
    agent.learn(8, failed=False, truncated=False)
    assert agent.action_weights[3] == pytest.approx(1000 * -0.95 * 0.1 * y0)
    assert agent.critic_weights[3] == pytest.approx(0.5 * -0.95 * 0.2)


@pytest.mark.parametrize("failed, expected_r_hat", [(True, -1.0), (False, 0.95 * -0.5)])
def test_failure_is_reinforced_minus_one_and_truncation_bootstraps(failed, expected_r_hat):
    agent = AseAce(AseAceParams(), np.random.default_rng(0))
    agent.critic_weights[40] = -0.5
    y = 2 * agent.act(82) - 1
    agent.learn(None if failed else 40, failed=failed, truncated=not failed)
    assert agent.action_weights[82] == pytest.approx(1000 * expected_r_hat * 0.1 * y)
    assert agent.critic_weights[82] == pytest.approx(0.5 * expected_r_hat * 0.2)
    assert not agent.eligibility.any() and not agent.input_trace.any()


def test_train_passes_truncation_as_no_failure(monkeypatch):
    calls = []
    learn = AseAce.learn

    def recording_learn(self, next_box, failed, truncated):
        calls.append((next_box is None, failed, truncated))
        learn(self, next_box, failed, truncated)

    monkeypatch.setattr(ase_ace.AseAce, "learn", recording_learn)
    returns = train(0, 3, env_factory=lambda: gymnasium.make("CartPole-v1", max_episode_steps=5))
    assert returns.tolist() == [5, 5, 5]
    assert calls == ([(False, False, False)] * 4 + [(False, False, True)]) * 3


def test_training_is_deterministic_for_a_seed():
    first = train(3, 30)
    assert np.array_equal(first, train(3, 30))
    assert not np.array_equal(first, train(4, 30))
    assert ((first >= 1) & (first <= 500)).all()


def test_training_stops_at_the_solving_episode():
    returns = train(5, 1000)
    assert solved_episode(returns) == len(returns)
    assert solved_episode(returns[:-1]) is None


def test_learning_raises_the_return():
    """Measured over seeds 0..39 (100 episodes each): episodes 1-20 average 33-249 per seed
    (median 66), episodes 81-100 average 314-500 (median 482); every 3-seed group's gain is over
    330. A random policy stays near 22."""
    returns = np.array([train(seed, 100) for seed in (0, 1, 2)])
    first, last = returns[:, :20].mean(), returns[:, -20:].mean()
    assert last >= 300
    assert last - first >= 200
