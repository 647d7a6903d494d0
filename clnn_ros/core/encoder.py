"""The 1-hot encoder of Table 1: each state variable's range is cut into intervals, lower-inclusive
[a, b), and the interval the value falls in spikes. Several variables are concatenated.

    angle (deg):      [-12,-6) [-6,-1) [-1,0) [0,1) [1,6) [6,12]      6 inputs
    cart velocity:    (-inf,-e) [-e,e) [e,+inf)                        3 inputs (e = 5 m/s in Table 1)

Beyond the paper, any of the four state variables in any order (Params.state_vars), each with
its edges as parameters (Params.edges_of), and any other task's named variables
(core.task.Task.variables, their edges in Params.variable_edges). Only the interior edges
matter: a value below the first edge falls in the first interval, one at or above the last in
the last (the environment fails the trial before the angle leaves +-12 deg).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .jitable import tick_kernel
from .params import STATE_NAMES, Params, ParamError

STATE_UNITS = ("m", "m/s", "deg", "deg/s")


@dataclass(frozen=True)
class Encoder:
    """Which components of the observation are encoded (indices into its vector), their interior
    edges, and every component's name and unit (the inputs' labels)."""

    components: tuple[int, ...]
    edges: tuple[tuple[float, ...], ...]
    names: tuple[str, ...] = STATE_NAMES  # of the observation's components, in its order
    units: tuple[str, ...] = STATE_UNITS

    @classmethod
    def from_params(cls, p: Params, names: tuple[str, ...] = STATE_NAMES,
                    units: tuple[str, ...] = STATE_UNITS) -> "Encoder":
        """The encoder of p.state_vars in an observation of these components (the cart-pole's
        state, or a task's variables); ParamError where p encodes a variable it lacks."""
        missing = [v for v in p.state_vars if v not in names]
        if missing:
            raise ParamError(f"state_vars: the observation has no {missing[0]!r}; it has "
                             f"{', '.join(names)}")
        return cls(tuple(names.index(v) for v in p.state_vars),
                   tuple(p.edges_of(v) for v in p.state_vars), tuple(names), tuple(units))

    @property
    def n_inputs(self) -> int:
        return sum(len(e) + 1 for e in self.edges)

    @cached_property
    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(components, edges padded with +inf, offsets) as arrays for encode_active()."""
        width = max(len(e) for e in self.edges)
        padded = np.full((len(self.edges), width), np.inf)
        offsets = np.zeros(len(self.edges), dtype=np.int64)
        for i, e in enumerate(self.edges):
            padded[i, :len(e)] = e
            offsets[i] = sum(len(prev) + 1 for prev in self.edges[:i])
        return np.array(self.components, dtype=np.int64), padded, offsets

    def labels(self) -> list[str]:
        """Human-readable names of the inputs, e.g. 'pole_angle[-1,0)deg'."""
        labels = []
        for component, edges in zip(self.components, self.edges):
            bounds = (-np.inf, *edges, np.inf)
            name, unit = self.names[component], self.units[component]
            for lo, hi in zip(bounds[:-1], bounds[1:]):
                labels.append(f"{name}[{lo:g},{hi:g}){unit}")
        return labels

    def active(self, state) -> np.ndarray:
        """Indices of the spiking inputs (one per encoded variable)."""
        components, edges, offsets = self.arrays
        out = np.empty(len(components), dtype=np.int64)
        encode_active(np.asarray(state, dtype=np.float64), components, edges, offsets, out)
        return out

    def spikes(self, state) -> np.ndarray:
        """The spike vector: 1 where the input spikes, 0 elsewhere (uint8, n_inputs long)."""
        vector = np.zeros(self.n_inputs, dtype=np.uint8)
        vector[self.active(state)] = 1
        return vector


@tick_kernel
def encode_active(state, components, edges, offsets, out):
    """Write into `out` the index of the spiking input of each encoded variable: the interval is
    the number of interior edges <= value (lower-inclusive intervals)."""
    for v in range(components.shape[0]):
        value = state[components[v]]
        interval = 0
        for k in range(edges.shape[1]):
            if value >= edges[v, k]:
                interval += 1
        out[v] = offsets[v] + interval
