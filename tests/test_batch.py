"""The numba batch engine equals the reference core trial by trial and in the final weights."""

import numpy as np
import pytest

from clnn_ros.batch import evaluate_weights_batch, run_batch
from clnn_ros.core.episode import evaluate_weights, run_episode
from clnn_ros.core.optimal import optimal_weights
from clnn_ros.core.physics import GYM_PHYSICS
from clnn_ros.core.params import (DECAY_COUNTERS, E_FLAGS, FIRST_ACTION, INFERENCE, INTEGRATORS,
                                  PHYSICS, PROTOCOLS, PUNISH_TIMING, SUCCESS_COUNTER, TAGGING,
                                  TIE_BREAKS, Params)

SEEDS = [0, 5, 11]
# Trials capped at 600 steps: each case still earns many rewards, and the pure-Python core, the
# reference, costs 57 CPU-s for all cases instead of 138 at 2,500 (the 10,000 cap: below).
MAX_STEPS = 600

# (options, whether some trial lasts beyond sigma steps, so rewards are exercised too). Trials
# under index ties and correct physics stay short: a small sigma rewards them all the same.
CASES = {
    "1sv paper": (dict(nsv=1), True),
    "1sv correct": (dict(nsv=1, physics="correct"), True),
    "2sv paper edge 5": (dict(nsv=2), True),
    "2sv paper edge 0.5": (dict(nsv=2, velocity_edge=0.5), True),
    "2sv correct euler": (dict(nsv=2, physics="correct", integrator="euler", velocity_edge=0.2,
                               sigma=16), True),
    "random ties": (dict(nsv=1, tie_break="random"), True),
    "random ties 2sv": (dict(nsv=2, velocity_edge=0.5, tie_break="random"), True),
    "index ties": (dict(nsv=1, tie_break="index", sigma=16), True),
    "index ties, both tagged": (dict(nsv=2, tie_break="index", tagging="both_neurons", sigma=16),
                                True),
    "both tagged": (dict(nsv=1, tagging="both_neurons"), True),
    "carried counter": (dict(nsv=1, success_counter="carry"), True),
    "live e 2sv": (dict(nsv=2, velocity_edge=0.5, e_flag="live"), True),
    "live e, carried counter": (dict(nsv=1, e_flag="live", success_counter="carry"), True),
    "integration slip": (dict(nsv=1, physics="integration_slip"), True),
    "carried decay counters": (dict(nsv=1, decay_counters="carry"), True),
    "carried decay counters 2sv": (dict(nsv=2, velocity_edge=0.5, decay_counters="carry"), True),
    "no force first": (dict(nsv=1, first_action="no_force"), True),
    "punished after decay": (dict(nsv=1, punish_timing="after_decay"), True),
    "exact inference": (dict(nsv=2, velocity_edge=0.5, inference="exact"), True),
    "3 state variables": (dict(nsv=3), True),
    "4 state variables": (dict(nsv=4, segments=12), True),
    "angle and position": (dict(state_vars="cart_position,pole_angle"), True),
    "exploring": (dict(nsv=1, explore=0.002), True),
    "exploring, random ties": (dict(nsv=2, velocity_edge=0.5, explore=0.01, tie_break="random"),
                               True),
    "re-randomized": (dict(nsv=1, rerandomize_every=4, rerandomize_fraction=0.2,
                           rerandomize_range=2.0), True),
    "re-randomized, exploring, random ties": (dict(nsv=2, velocity_edge=0.5, explore=0.01,
                                                   tie_break="random", rerandomize_every=3,
                                                   rerandomize_fraction=0.5), True),
    # Gymnasium's step in radians, from the paper's starts in degrees, released first
    "gymnasium physics": (dict(nsv=1, physics="gymnasium", first_action="no_force"), True),
    # CartPole-v1's protocol (starts in radians, truncated at 500) on the paper's physics, and
    # on CartPole-v1's own
    "gymnasium protocol": (dict(nsv=1, protocol="gymnasium", max_steps=500), True),
    "gymnasium protocol and physics": (dict(nsv=2, velocity_edge=0.5, protocol="gymnasium",
                                            max_steps=500, sigma=16,
                                            **{**GYM_PHYSICS, "physics": "gymnasium"}), True),
}

OPTIONS = {"tie_break": TIE_BREAKS, "tagging": TAGGING, "e_flag": E_FLAGS,
           "success_counter": SUCCESS_COUNTER, "physics": PHYSICS, "integrator": INTEGRATORS,
           "decay_counters": DECAY_COUNTERS, "first_action": FIRST_ACTION,
           "punish_timing": PUNISH_TIMING, "inference": INFERENCE, "nsv": (1, 2, 3, 4),
           "protocol": PROTOCOLS}


@pytest.mark.parametrize("option", OPTIONS)
def test_every_option_value_is_a_rewarded_case(option):
    default = getattr(Params(), option)
    covered = {options.get(option, default) for options, rewarded in CASES.values() if rewarded}
    assert covered == set(OPTIONS[option])


@pytest.mark.parametrize("case", CASES)
def test_batch_equals_core(case):
    options, rewarded = CASES[case]
    p = Params(**{"trials": 48, "max_steps": MAX_STEPS, **options})
    batch = run_batch(SEEDS, p)
    for k, seed in enumerate(SEEDS):
        core = run_episode(seed, p)
        np.testing.assert_array_equal(batch.steps[k], core.steps, err_msg=f"seed {seed}")
        np.testing.assert_array_equal(batch.end_status[k], core.end_status)
        np.testing.assert_array_equal(batch.initial_angles[k], core.initial_angles)
        np.testing.assert_array_equal(batch.final_weights[k], core.final_weights)  # bit for bit
    assert (batch.steps.max() > p.sigma) == rewarded


def test_batch_equals_core_with_default_cap():
    p = Params(trials=24)
    batch = run_batch([3], p)
    core = run_episode(3, p)
    np.testing.assert_array_equal(batch.steps[0], core.steps)
    np.testing.assert_array_equal(batch.final_weights[0], core.final_weights)


@pytest.mark.parametrize("nsv, edge", [(1, 5.0), (2, 0.5)])
def test_fixed_weights_equal(nsv, edge):
    p = Params(nsv=nsv, velocity_edge=edge, max_steps=3000)
    core = evaluate_weights(optimal_weights(nsv), p)
    batch = evaluate_weights_batch(optimal_weights(nsv), p)
    np.testing.assert_array_equal(batch.steps[0], core.steps)
    np.testing.assert_array_equal(batch.final_weights[0], optimal_weights(nsv))
