"""The hand-set optimal weights of Figure 7 (1 state variable) and Figure 12 (2 state variables).

Each segment has weight 8 (w_max) on the inputs of one input pattern and 0 elsewhere, so every
pattern drives exactly one segment to 8 per spiking input and the network WTA has no ties.
Inputs are numbered from 1 as in the paper: angle intervals 1-6, then velocity intervals 1-3.
"""

import numpy as np

# Figure 7: one angle interval per segment. -F handles the left-leaning intervals 1-3,
# +F the right-leaning 6, 5, 4 (in the figure's segment order).
FIGURE7_PATTERNS = (((1,), (2,), (3,)),
                    ((6,), (5,), (4,)))

# Figure 12: (angle interval, velocity interval) per segment, rows in the figure's order.
FIGURE12_PATTERNS = (((1, 2), (1, 3), (2, 2), (2, 3), (3, 1), (3, 3), (4, 2), (5, 3), (6, 3)),
                     ((6, 2), (6, 1), (5, 2), (5, 1), (4, 3), (4, 1), (3, 2), (2, 1), (1, 1)))


def optimal_weights(nsv: int, w_max: float = 8.0) -> np.ndarray:
    """Weights [neuron (0 = -F, 1 = +F), segment, input] of Figure 7 (nsv=1) or Figure 12 (nsv=2)."""
    if nsv not in (1, 2):
        raise ValueError(f"nsv must be 1 or 2, got {nsv!r}")
    patterns = FIGURE7_PATTERNS if nsv == 1 else FIGURE12_PATTERNS
    weights = np.zeros((2, len(patterns[0]), 6 if nsv == 1 else 9))
    for neuron, segments in enumerate(patterns):
        for segment, pattern in enumerate(segments):
            angle_input = pattern[0] - 1
            weights[neuron, segment, angle_input] = w_max
            if nsv == 2:
                weights[neuron, segment, 6 + pattern[1] - 1] = w_max
    return weights
