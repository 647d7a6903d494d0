"""The numba batch engine equals the reference core trial by trial and in the final weights."""

import numpy as np
import pytest

from clnn_ros.batch import evaluate_weights_batch, run_batch
from clnn_ros.core.episode import evaluate_weights, run_episode
from clnn_ros.core.optimal import optimal_weights
from clnn_ros.core.params import Params

SEEDS = [0, 5, 11]

# (options, whether some trial lasts beyond sigma = 256 steps, so rewards are exercised too)
CASES = {
    "1sv paper": (dict(nsv=1), True),
    "1sv correct": (dict(nsv=1, physics="correct"), True),
    "2sv paper edge 5": (dict(nsv=2), True),
    "2sv paper edge 0.5": (dict(nsv=2, velocity_edge=0.5), True),
    "2sv correct euler": (dict(nsv=2, physics="correct", integrator="euler", velocity_edge=0.2),
                          False),
    "random ties": (dict(nsv=1, tie_break="random"), True),
    "index ties, both tagged": (dict(nsv=2, tie_break="index", tagging="both_neurons"), False),
    "live e, carried counter": (dict(nsv=1, e_flag="live", success_counter="carry"), True),
}


@pytest.mark.parametrize("case", CASES)
def test_batch_equals_core(case):
    options, rewarded = CASES[case]
    p = Params(trials=48, max_steps=2500, **options)
    batch = run_batch(SEEDS, p)
    for k, seed in enumerate(SEEDS):
        core = run_episode(seed, p)
        np.testing.assert_array_equal(batch.steps[k], core.steps, err_msg=f"seed {seed}")
        np.testing.assert_array_equal(batch.end_status[k], core.end_status)
        np.testing.assert_array_equal(batch.initial_angles[k], core.initial_angles)
        np.testing.assert_array_equal(batch.final_weights[k], core.final_weights)  # bit for bit
    assert (batch.steps.max() > 256) == rewarded


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
