"""The batch engine's scheduling changes nothing: seeds from the shared queue, two lanes per
thread (a lane left alone, a lane taking a new seed, a trial at the step cap as a seed's last),
one thread or two, every result equals the reference core's, bit for bit; and the compiled
sin and cos pair equals Python's."""

import math

import numba
import numpy as np
import pytest

from clnn_ros.batch import run_batch
from clnn_ros.core.episode import run_episode
from clnn_ros.core.params import Params


def assert_equals_core(batch, seeds, p):
    for k, seed in enumerate(seeds):
        core = run_episode(seed, p)
        np.testing.assert_array_equal(batch.steps[k], core.steps, err_msg=f"seed {seed}")
        np.testing.assert_array_equal(batch.end_status[k], core.end_status)
        np.testing.assert_array_equal(batch.final_weights[k], core.final_weights)


# Seven seeds: the queue refills lanes of different lengths. A cap of 40 steps ends many trials
# at the cap, the seeds' last ones too (a lane then idles with its clock at the cap).
@pytest.mark.parametrize("options", [dict(nsv=1, max_steps=40, trials=24),
                                     dict(nsv=2, velocity_edge=0.5, max_steps=150, trials=16,
                                          sigma=16, tie_break="random", explore=0.01)])
def test_many_seeds_equal_core(options):
    p = Params(**options)
    seeds = [3, 1, 4, 15, 9, 2, 6]
    batch = run_batch(seeds, p)
    assert (batch.steps[:, -1] == p.max_steps).any() or options["nsv"] == 2
    assert_equals_core(batch, seeds, p)


@pytest.mark.parametrize("seeds", [[7], [7, 8]])
def test_fewer_seeds_than_lanes(seeds):
    p = Params(nsv=1, trials=12, max_steps=300)
    assert_equals_core(run_batch(seeds, p), seeds, p)


def test_threads_change_nothing():
    p = Params(nsv=1, trials=16, max_steps=400)
    seeds = list(range(9))
    before = numba.get_num_threads()
    results = []
    try:
        for threads in sorted({1, min(2, numba.config.NUMBA_NUM_THREADS)}):
            numba.set_num_threads(threads)
            results.append(run_batch(seeds, p))
    finally:
        numba.set_num_threads(before)
    for other in results[1:]:
        np.testing.assert_array_equal(other.steps, results[0].steps)
        np.testing.assert_array_equal(other.final_weights, results[0].final_weights)
    assert_equals_core(results[0], seeds, p)


def test_compiled_sin_cos_pair_equals_python():
    """Compiled, math.sin and math.cos of one angle in one block become one call of libm's
    sincos (LLVM joins them; the batch engine's tick loop has them so). glibc's sincos takes the
    very paths of sin and cos below 0.855 rad, and Params keeps the pole within 12 deg: equal
    bits there, checked here on a dense sample and across the band (2^-27, 2^-26) where sin
    returns x itself."""
    @numba.njit
    def pair(xs, out):
        for k in range(xs.shape[0]):
            out[k, 0], out[k, 1] = math.sin(xs[k]), math.cos(xs[k])

    limit = math.radians(12.0)
    rng = np.random.default_rng(0)
    xs = np.concatenate([np.linspace(-limit, limit, 200_001), rng.uniform(-limit, limit, 200_000),
                         rng.uniform(2.0**-28, 2.0**-25, 20_000) * rng.choice([-1, 1], 20_000)])
    out = np.empty((xs.size, 2))
    pair(xs, out)
    assert out[:, 0].tolist() == [math.sin(x) for x in xs.tolist()]
    assert out[:, 1].tolist() == [math.cos(x) for x in xs.tolist()]
