"""A tiny counter-based random stream (splitmix64) that the core and the numba batch engine draw
from identically, so even the `tie_break="random"` option is reproducible across paths."""

import numpy as np

from .jitable import jitable


@jitable
def next_uniform(state):
    """Advance state[0] (a uint64 array of length 1) and return a float in [0, 1)."""
    state[0] = state[0] + np.uint64(0x9E3779B97F4A7C15)
    z = state[0]
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) / 9007199254740992.0
