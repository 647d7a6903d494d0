"""The core's functions that the numba batch engine compiles, marked without importing numba.

A marked function is plain Python when called from Python (the nodes, the reference core). The
batch engine (clnn_ros.batch) registers every marked function with numba's `register_jitable`
before it compiles, so it runs this very code. Numba is not imported here: it is two thirds of
a node's start-up (0.7 s of CPU in each of a graph's processes, measured with -X importtime).
"""

from __future__ import annotations

from typing import Callable

# (function, register_jitable's options), in the order they were marked
MARKED: list[tuple[Callable, dict]] = []


def jitable(function: Callable | None = None, **options):
    """@jitable or @jitable(**options): mark `function` for register_jitable(**options)."""
    def mark(function: Callable) -> Callable:
        MARKED.append((function, options))
        return function
    return mark if function is None else mark(function)


# How the core's functions are compiled into the batch engine. Its tick loop runs without numba's
# reference counting, which would cost more there than the tick's own work: the functions called
# on every tick are inlined into it (tick_kernel), the others are compiled without reference
# counting too (kernel; none of them makes an array).
kernel = jitable(_nrt=False)


def tick_kernel(function: Callable) -> Callable:
    return jitable(function, inline="always")
