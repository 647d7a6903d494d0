"""The run setting `init_weights` (run_all --init-weights, the nodes' ROS parameter): which text
names which start of an episode. The core takes the typed result (weights, a Checkpoint); the
names and file endings are the command line's. No ROS import.

    ""                 a new episode with the seed's weights
    fig7, fig12        a new episode with the optimal weights of Figure 7 (1 SV) or 12 (2 SV)
    WEIGHTS.npy        a new episode with these weights, shape (2, segments, inputs)
    CHECKPOINT.npz     resume the checkpoint's episode at its next trial
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checkpoint import (Checkpoint, CheckpointError, check_resumable, first_line,
                              load_checkpoint, restore_counter)
from .optimal import optimal_weights
from .params import Params
from .agent import SuccessCounter

# The names of the optimal weights, and the state variables they are made for.
OPTIMAL = {"fig7": 1, "fig12": 2}


@dataclass(frozen=True)
class EpisodeStart:
    """How an episode begins: new with `weights` (None: the seed's) or continuing `resume`."""

    weights: np.ndarray | None = None
    resume: Checkpoint | None = None

    @property
    def first_trial(self) -> int:
        return 0 if self.resume is None else self.resume.next_trial

    def success_counter(self, params: Params) -> SuccessCounter:
        """The success counter at the first trial: a new one, or the count the checkpoint
        carried."""
        return SuccessCounter(params) if self.resume is None else restore_counter(self.resume)


def episode_start(setting: str, seed: int, params: Params,
                  compared: tuple[str, ...] | None = None) -> EpisodeStart:
    """The start that `setting` names for an episode of `seed` and `params`; CheckpointError (a
    ParamError) with one line for a name or file that does not fit them. `compared`: the
    parameters a resumed checkpoint must agree on (a node's own; None: all)."""
    if setting.endswith(".npz"):
        checkpoint = load_checkpoint(setting)
        check_resumable(checkpoint, params, seed, compared)
        return EpisodeStart(resume=checkpoint)
    return EpisodeStart(weights=load_weights(setting, params) if setting else None)


def load_weights(source: str, params: Params) -> np.ndarray:
    """Initial weights from "fig7" / "fig12" (the optimal weights at w_max) or a `.npy` file of
    shape (2, segments, inputs) with values in [0, w_max]; CheckpointError with one line
    otherwise."""
    shape = (params.n_actions, params.n_segments, params.n_inputs)
    if source in OPTIMAL:
        weights = optimal_weights(OPTIMAL[source], params.w_max)
        if weights.shape != shape:
            raise CheckpointError(f"{source} weights are for nsv={OPTIMAL[source]} with the "
                                  f"paper's segments and angle edges, shape {weights.shape}; "
                                  f"this run's network has shape {shape} (nsv={params.nsv})")
        return weights
    if not source.endswith(".npy"):
        raise CheckpointError(f"init_weights must be fig7, fig12, a weights .npy or a checkpoint "
                              f".npz file, got {source!r}")
    try:
        weights = np.load(source, allow_pickle=False)
    except FileNotFoundError:
        raise CheckpointError(f"weights {source}: no such file") from None
    except (OSError, ValueError, EOFError) as error:
        raise CheckpointError(f"weights {source}: not a readable .npy file "
                              f"({first_line(error)})") from None
    if weights.shape != shape or weights.dtype.kind not in "fiu":
        raise CheckpointError(f"weights {source}: {weights.dtype} array of shape {weights.shape}, "
                              f"this run's network needs numbers of shape {shape} "
                              f"(nsv={params.nsv})")
    if not np.all((weights >= 0) & (weights <= params.w_max)):
        raise CheckpointError(f"weights {source}: values must lie in [0, w_max={params.w_max:g}]")
    return weights.astype(np.float64)
