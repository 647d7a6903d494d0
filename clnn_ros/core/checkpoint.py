"""Checkpoints: the state an episode continues from, in one numpy `.npz` file.

A checkpoint holds everything the rest of an episode depends on: the model parameters, the seed
(it fixes the initial angle of every trial), the index of the next trial, the agent's whole state
(weights, punishment and reward counters, e flags, last spikes, the tie-break random stream) and
the success counter (it carries across trials with success_counter="carry").

Saved at a trial boundary (trial_step == 0), it resumes exactly: the rest of the episode equals
that of an uninterrupted run bit for bit. Saved in the middle of a trial (trial_step > 0, e.g. on
request), it cannot: the cart's state lives in the environment, not in the agent. Resuming it
restarts that trial from its beginning with the agent's weights of that moment.
"""

from __future__ import annotations

import json
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .params import ParamError, Params
from .agent import RLNAgent, SuccessCounter

FORMAT = "clnn_ros.checkpoint"
FORMAT_VERSION = 1
# The scalars of the file besides the agent's arrays (stored as "agent_<name>").
SCALARS = ("seed", "next_trial", "trial_step", "tick", "success_count")


class CheckpointError(ParamError):
    """A checkpoint or weights file that cannot be used; its message is one line."""


@dataclass(frozen=True)
class Checkpoint:
    params: Params
    seed: int
    next_trial: int  # the first trial a resume runs
    trial_step: int  # ticks of trial next_trial already run when saved; 0 = at a trial boundary
    tick: int  # the tick of the saving run after which it was saved (-1: not saved by a graph)
    success_count: int
    agent: dict  # RLNAgent.state()

    @property
    def weights(self) -> np.ndarray:
        return self.agent["weights"]


def capture(agent: RLNAgent, counter: SuccessCounter, seed: int, next_trial: int,
            trial_step: int = 0, tick: int = -1) -> Checkpoint:
    """The checkpoint of a running agent and success counter."""
    return Checkpoint(agent.p, int(seed), int(next_trial), int(trial_step), int(tick),
                      int(counter.count), agent.state())


def save_checkpoint(path: str | os.PathLike, checkpoint: Checkpoint) -> Path:
    """Write `checkpoint` to `path` (.npz); the file is replaced at once (a crash while writing
    leaves the previous one). Returns the path."""
    path = Path(path)
    params = {k: list(v) if isinstance(v, tuple) else v
              for k, v in checkpoint.params.to_dict().items()}
    arrays = {f"agent_{name}": value for name, value in checkpoint.agent.items()}
    scalars = {name: np.int64(getattr(checkpoint, name)) for name in SCALARS}
    partial = path.with_name(path.name + ".partial")
    try:
        with open(partial, "wb") as f:
            np.savez(f, format=FORMAT, format_version=FORMAT_VERSION,
                     params_json=json.dumps(params), **scalars, **arrays)
        os.replace(partial, path)
    except OSError as error:  # a full disk: the previous checkpoint stays, named in the error
        partial.unlink(missing_ok=True)
        error.filename = error.filename or str(path)
        raise
    return path


def load_checkpoint(path: str | os.PathLike) -> Checkpoint:
    """Read and check a checkpoint file; CheckpointError with one line when it is missing,
    not a checkpoint, of another format version, or inconsistent."""
    try:
        with np.load(path, allow_pickle=False) as data:
            entries = {name: data[name] for name in data.files}
    except FileNotFoundError:
        raise CheckpointError(f"checkpoint {path}: no such file") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
        raise CheckpointError(f"checkpoint {path}: not a readable .npz file "
                              f"({first_line(error)})") from None
    if str(entries.get("format", "")) != FORMAT:
        raise CheckpointError(f"checkpoint {path}: not a clnn_ros checkpoint (no format "
                              f"'{FORMAT}')")
    version = entries.get("format_version")
    if version is None or version.shape or int(version) != FORMAT_VERSION:
        raise CheckpointError(f"checkpoint {path}: format version {version}, this clnn_ros "
                              f"reads version {FORMAT_VERSION}")
    try:
        params = Params(**json.loads(str(entries["params_json"])))
        scalars = {name: int(entries[name]) for name in SCALARS}
        state = {name: entries[f"agent_{name}"] for name in RLNAgent.STATE}
        agent = RLNAgent(params, state["weights"], seed=scalars["seed"])
        agent.load_state(state)
    except KeyError as error:
        raise CheckpointError(f"checkpoint {path}: entry {error} is missing") from None
    except (TypeError, ValueError) as error:  # ParamError included
        raise CheckpointError(f"checkpoint {path}: {first_line(error)}") from None
    if any(scalars[name] < 0 for name in ("seed", "next_trial", "trial_step", "success_count")):
        raise CheckpointError(f"checkpoint {path}: negative counts {scalars}")
    return Checkpoint(params, agent=agent.state(), **scalars)


def check_resumable(checkpoint: Checkpoint, params: Params, seed: int,
                    compared: tuple[str, ...] | None = None) -> None:
    """A resume continues the same episode: same seed and parameters (only the number of trials
    may change; `compared`: only these are looked at, None: all) and at least one trial left.
    CheckpointError with one line otherwise."""
    if seed != checkpoint.seed:
        raise CheckpointError(f"the checkpoint continues seed {checkpoint.seed}, this run has "
                              f"seed {seed}")
    # segments None stands for the paper's count for nsv: the count the network has is compared
    saved = {**checkpoint.params.to_dict(), "segments": checkpoint.params.n_segments}
    wanted = {**params.to_dict(), "segments": params.n_segments}
    differ = [k for k in saved if k != "trials" and saved[k] != wanted[k] and
              (compared is None or k in compared)]
    if differ:
        raise CheckpointError("the checkpoint was saved with " + ", ".join(
            f"{k}={saved[k]!r} (this run: {wanted[k]!r})" for k in differ)
            + "; a resume keeps every parameter but trials")
    if checkpoint.next_trial >= params.trials:
        raise CheckpointError(f"the checkpoint resumes at trial {checkpoint.next_trial + 1}, "
                              f"after the episode's trials={params.trials}: nothing left to run")


def restore(checkpoint: Checkpoint) -> tuple[RLNAgent, SuccessCounter]:
    """The agent and success counter of a checkpoint, as they were when it was saved."""
    agent = RLNAgent(checkpoint.params, checkpoint.weights, seed=checkpoint.seed)
    agent.load_state(checkpoint.agent)
    return agent, restore_counter(checkpoint)


def restore_counter(checkpoint: Checkpoint) -> SuccessCounter:
    """The success counter of a checkpoint, as it was when it was saved."""
    counter = SuccessCounter(checkpoint.params)
    counter.count = checkpoint.success_count
    return counter


def first_line(error: Exception) -> str:
    """The first line of an error's message (its type's name if it has none)."""
    return (str(error).strip().splitlines() or [type(error).__name__])[0]
