"""The reproduction's verdicts (clnn_ros.reproduce): each named threshold, on both sides."""

from __future__ import annotations

import numpy as np
import pytest

from clnn_ros.core.optimal import optimal_weights
from clnn_ros.core.params import Params
from clnn_ros.core.physics import CONTINUE, FAIL_ANGLE, FAIL_POSITION
from clnn_ros.reproduce import claims, figures
from clnn_ros.reproduce.calibration import ModeCalibration, best_edge
from clnn_ros.reproduce.common import PAPER, STUCK_BELOW, stuck
from clnn_ros.reproduce.physics_modes import MODE_FIT_TOLERANCE, mode_fits_paper

B = PAPER["constant_force_steps"]


@pytest.mark.parametrize("measured, verdict", [
    (PAPER["no_force_steps"] * (1 + claims.MATCH_TOLERANCE), True),
    (PAPER["no_force_steps"] * (1 + claims.MATCH_TOLERANCE) + 0.01, False),
    (PAPER["no_force_steps"] * (1 - claims.MATCH_TOLERANCE), True),
    (PAPER["no_force_steps"] * (1 - claims.MATCH_TOLERANCE) - 0.01, False),
])
def test_matches_within_tolerance(measured, verdict):
    assert claims.matches(measured, PAPER["no_force_steps"]) is verdict


@pytest.mark.parametrize("plus, minus, verdict", [
    ((B, FAIL_POSITION), (B, FAIL_POSITION), True),
    ((B + 1, FAIL_POSITION), (B, FAIL_POSITION), False),
    ((B, FAIL_POSITION), (B - 1, FAIL_POSITION), False),
    ((B, FAIL_ANGLE), (B, FAIL_POSITION), False),
])
def test_constant_force_matches(plus, minus, verdict):
    assert claims.constant_force_matches(plus, minus) is verdict


GRID = np.linspace(-1.5, 1.5, 32)
NEAREST_ZERO = int(np.argmin(np.abs(GRID)))
LOW = PAPER["fig8_low"] * (1 - claims.MATCH_TOLERANCE)
HIGH = PAPER["fig8_high"] * (1 + claims.MATCH_TOLERANCE)


@pytest.mark.parametrize("rest_low, rest_high, capped_index, verdict", [
    (LOW, HIGH, NEAREST_ZERO, True),
    (LOW - 1, HIGH, NEAREST_ZERO, False),
    (LOW, HIGH + 1, NEAREST_ZERO, False),
    (LOW, HIGH, 0, False),  # capped, but not the angle nearest 0
])
def test_fig8_same_pattern(rest_low, rest_high, capped_index, verdict):
    status = np.full(32, FAIL_POSITION)
    status[capped_index] = CONTINUE
    steps = np.full(32, (LOW + HIGH) / 2)
    steps[capped_index] = 10_000
    others = [k for k in range(32) if k != capped_index]
    steps[others[0]], steps[others[1]] = rest_low, rest_high
    assert claims.fig8_same_pattern(GRID, steps, status) is verdict


def test_fig8_needs_a_trial_below_the_cap():
    assert not claims.fig8_same_pattern(GRID, np.full(32, 10_000), np.full(32, CONTINUE))


def test_nearly_all_capped():
    assert claims.nearly_all_capped(claims.NEARLY_ALL_CAPPED)
    assert not claims.nearly_all_capped(claims.NEARLY_ALL_CAPPED - 1)


def test_typically_by_cart():
    assert claims.typically_by_cart(claims.TYPICALLY_BY_CART)
    assert not claims.typically_by_cart(claims.TYPICALLY_BY_CART - 0.01)


def test_near_optimal():
    opt1 = 6000.0
    means = np.array([claims.NEAR_OPTIMAL * opt1, claims.NEAR_OPTIMAL * opt1 - 1])
    assert claims.near_optimal(means, opt1).tolist() == [True, False]


def test_fig14_bands():
    opt1 = 6000.0
    better, worse = claims.FIG14_BETTER * opt1, claims.FIG14_WORSE * opt1
    means = np.array([better + 1, better, worse, worse - 1])
    assert claims.fig14_counts(means, opt1) == (1, 2, 1)


def test_stuck():
    assert stuck(np.array([STUCK_BELOW - 1, STUCK_BELOW, STUCK_BELOW + 1])) == 1


def _mode(no_force_mean: float, plus=(B, FAIL_POSITION)) -> ModeCalibration:
    zeros = np.zeros(32, int)
    return ModeCalibration(no_force_steps=np.full(32, no_force_mean), no_force_status=zeros,
                           plus=plus, minus=(B, FAIL_POSITION), fig7_steps=zeros,
                           fig7_status=zeros, fig12_steps=zeros[None], fig12_status=zeros[None],
                           best_edge=5.0)


def test_mode_fits_paper():
    limit = PAPER["no_force_steps"] * (1 + MODE_FIT_TOLERANCE)
    assert mode_fits_paper(_mode(limit))
    assert not mode_fits_paper(_mode(limit + 0.01))
    assert not mode_fits_paper(_mode(PAPER["no_force_steps"], plus=(B, FAIL_ANGLE)))


@pytest.mark.parametrize("means, edge", [
    ([1, 5, 5, 5], 3.0),  # a plateau of three: its middle
    ([5, 5, 1, 1], 1.0),  # a plateau of two: the lower middle
    ([1, 2, 9, 3], 3.0),
])
def test_best_edge(means, edge):
    assert best_edge([1.0, 2.0, 3.0, 4.0], means) == edge


@pytest.mark.parametrize("max_angle, like_1sv", [
    (figures.CENTRAL_SPAN_DEG - 0.01, True),
    (figures.CENTRAL_SPAN_DEG, False),
])
def test_fig15_note_like_1sv_only_inside_the_central_intervals(monkeypatch, max_angle, like_1sv):
    monkeypatch.setattr(figures, "velocity_ignored", lambda w, p: list(figures.CENTRAL_INTERVALS))
    states = np.zeros((10, 4))
    states[3, 2] = -max_angle
    trace = figures.Trace(seed=0, seed_mean=9000.0, trial=300, angle=0.1,
                          weights=optimal_weights(2), params=Params(nsv=2), steps=10_000,
                          status=CONTINUE, states=states, first=5000)
    note = figures.fig15_note(trace)
    assert note.endswith("so it moves like a 1-SV trial.") is like_1sv
    assert "interval(s) 3, 4" in note


def test_figure15_seed_rule_wants_the_velocity_used_in_a_central_interval():
    p = Params(nsv=2)
    assert figures.uses_velocity(optimal_weights(2), p)
    blind = optimal_weights(2).copy()
    blind[:, :, 6:] = 0.0  # no velocity synapse: the velocity input never decides
    assert not figures.uses_velocity(blind, p)


def test_velocity_ignored_by_figure12_weights():
    """The Figure 12 weights use the velocity somewhere (else 2 SV would be 1 SV)."""
    ignored = figures.velocity_ignored(optimal_weights(2), Params(nsv=2))
    assert set(ignored) < set(range(1, 7))
