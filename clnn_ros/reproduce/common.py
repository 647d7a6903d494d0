"""What the experiments share: the paper's numbers, the run sizes, the velocity-edge scan, the
physics modes, the stuck threshold, and small helpers (seed specs, CSV, tables, progress bars, one
replayed trial)."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numba
import numpy as np
from tqdm import tqdm

from .. import batch
from ..batch import BatchResult, run_batch
from ..core.encoder import Encoder
from ..core.episode import run_trial
from ..core.params import Params
from ..core.physics import CartPole, at_rest
from ..core.agent import RLNAgent, SuccessCounter

# ------------------------------------------------------------------------------------------------
# Settings
# ------------------------------------------------------------------------------------------------
PAPER = {  # the paper's own numbers (section 3.1, 3.2, 4.1, 4.2)
    "no_force_steps": 275,  # (a) pole falls with no force
    "constant_force_steps": 32,  # (b) cart leaves the track under constant +F or -F
    "fig7_mean": 6380,  # (c) Figure 7 weights, mean over the 32 initial angles
    "fig8_low": 3000, "fig8_high": 9000,  # Figure 8: non-capped angles fall between these
    "fig14_better": 3, "fig14_same": 12,  # Figure 14: "three clearly better, another 12 about the
    "fig14_worse": 16,  # same, about half worse" than 1 SV (half of 32)
}
DEFAULT_SEEDS = "0-31"  # the paper's 32 episodes
TRIALS = 512  # trials per episode
MAX_STEPS = Params().max_steps  # every run's trial cap: the paper's 10,000
LITERAL_EDGE = 5.0  # Table 1's velocity edge, m/s
EDGE_SCAN = tuple(float(e) for e in np.round(np.geomspace(0.05, 5.0, 25), 4))  # 0.05 .. 5, log-spaced
PAPER_MODE = ("paper", "semi_implicit")  # the project's defaults, where the paper's numbers are met
MODES = (PAPER_MODE, ("paper", "euler"),
         ("correct", "semi_implicit"), ("correct", "euler"))  # physics x integrator
# "Stuck": a seed whose mean successful steps stay below this, under a sixth of the paper's
# Figure 7 mean (6,380): it has not learned to balance.
STUCK_BELOW = 1000
END_REASONS = {0: "max_steps", 1: "pole_angle", 2: "cart_position"}  # physics status -> CSV text


# ------------------------------------------------------------------------------------------------
# Helpers
# ------------------------------------------------------------------------------------------------
class SeedMeans:
    """For a result that holds `steps`, (seeds, trials): each seed's mean successful steps."""

    steps: np.ndarray

    @property
    def seed_means(self) -> np.ndarray:
        return self.steps.mean(axis=1)


def parse_seeds(spec: str) -> list[int]:
    """'0-31', '0,3,5' or '0-3,7' -> sorted seeds; ValueError with one line on bad input."""
    seeds: list[int] = []
    text = str(spec).strip()
    if not text:
        raise ValueError("seed spec is empty; use e.g. 0-31, 0,3,5 or 0-3,7")
    for part in text.split(","):
        part = part.strip()
        lo, sep, hi = part.partition("-")
        try:
            first = int(lo, 10)
            last = int(hi, 10) if sep else first
        except ValueError:
            raise ValueError(f"bad seed spec {spec!r}: {part!r} is not N or N-M "
                             f"(non-negative integers); use e.g. 0-31, 0,3,5 or 0-3,7") from None
        if first < 0 or last < first:
            raise ValueError(f"bad seed spec {spec!r}: range {part!r} must be N-M with 0 <= N <= M")
        seeds.extend(range(first, last + 1))
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"bad seed spec {spec!r}: a seed appears twice")
    return sorted(seeds)


def end_reason(status: int) -> str:
    return END_REASONS[int(status)]


def mode_label(physics: str, integrator: str) -> str:
    return f"{physics}/{integrator}"


def stuck(means: np.ndarray) -> int:
    """How many seeds are stuck (mean below STUCK_BELOW)."""
    return int(np.sum(means < STUCK_BELOW))


def write_csv(path: Path, header: list[str], rows) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def md_table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |" for row in rows]
    return "\n".join(lines)


def progress(items, desc: str):
    """A tqdm bar on stderr (hidden when stderr is not a terminal)."""
    return tqdm(items, desc=desc, leave=False, disable=None, file=sys.stderr)


def trace_trial(weights: np.ndarray, angle_deg: float, p: Params, learn: bool = False,
                seed: int = 0) -> tuple[np.ndarray, int, int]:
    """Replay one trial through the core, from these weights at its start; (states (steps+1, 4),
    steps, status). Row 0 is the initial state, row k the state after step k."""
    agent = RLNAgent(p, weights, seed=seed)
    env = CartPole(p)
    states = [env.reset(at_rest(angle_deg))]
    steps, status = run_trial(agent, SuccessCounter(p), env, Encoder.from_params(p), p,
                              learn=learn, trace=states.append)
    return np.array(states), steps, status


def load_stored(path: Path) -> dict | None:
    """The arrays stored at `path`, or None when nothing is stored there."""
    if not path.exists():
        return None
    with np.load(path) as data:
        return dict(data)


def store_arrays(path: Path, arrays: dict) -> None:
    """Store a dict of arrays at `path` atomically: written whole to a file of this process's
    own beside it, flushed to disk, then renamed over `path` (a reader sees all or nothing; an
    interruption leaves nothing under `path`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f"{path.name}.{os.getpid()}.partial")
    try:
        with open(partial, "wb") as f:
            np.savez_compressed(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)


def stored(path: Path, compute) -> dict:
    """The arrays stored at `path`, or compute()'s (a dict of arrays) stored there first, written
    whole at once: an interrupted study or sweep resumes with what it finished."""
    arrays = load_stored(path)
    if arrays is None:
        arrays = compute()
        store_arrays(path, arrays)
    return arrays


def store_path(store: Path, name: str, key) -> Path:
    """Where a run named `name` is stored: the name made safe for a file, and a digest of `key`
    (what the run depends on, e.g. its parameters and seeds)."""
    safe = "".join(c if c.isalnum() else "_" for c in name)[:80]
    digest = hashlib.sha256(json.dumps(key, sort_keys=True, default=list).encode()).hexdigest()
    return store / f"{safe}_{digest[:16]}.npz"


# ------------------------------------------------------------------------------------------------
# Units of work: one configuration x a block of seeds
# ------------------------------------------------------------------------------------------------
# A run of the batch engine (parameters, seeds) is cut into units of SEED_BLOCK seeds. Each seed's
# episode depends on its seed and the parameters only, so a run's arrays are its units' arrays
# one after another, whoever ran them and in whatever order. A unit is what a store keeps (one
# file each: a finished unit is not run again) and what a cluster worker runs (8 seeds x 512
# trials: a few seconds on one core). The store's file names depend on the block, so a stored
# run resumes only with the same block.
SEED_BLOCK = 8
LOCAL_SEEDS = 32  # this machine runs at least this many seeds of one configuration in one call
UNIT_ARRAYS = ("steps", "end_status", "final_weights", "initial_angles")


def run_unit(p: Params, seeds) -> dict:
    """A unit's arrays (UNIT_ARRAYS, one row per seed): the batch engine's run of p on seeds."""
    r = run_batch(seeds, p)
    return dict(steps=r.steps, end_status=r.end_status, final_weights=r.final_weights,
                initial_angles=r.initial_angles)


class LocalExecutor:
    """Runs units in this process, several units of one configuration in one call of the batch
    engine (its threads share the seeds), so that a small block costs no speed here."""

    workers = 1
    where = "this machine"

    def run(self, units: list[tuple[Params, np.ndarray]]):
        """(index in units, arrays) for each unit, as they finish."""
        most = max(LOCAL_SEEDS, numba.get_num_threads())
        k = 0
        while k < len(units):
            p, group = units[k][0], [k]
            while (group[-1] + 1 < len(units) and units[group[-1] + 1][0] == p
                   and sum(len(units[j][1]) for j in group) < most):
                group.append(group[-1] + 1)
            arrays = run_unit(p, np.concatenate([units[j][1] for j in group]))
            start = 0
            for j in group:
                size = len(units[j][1])
                yield j, {key: value[start:start + size] for key, value in arrays.items()}
                start += size
            k = group[-1] + 1


_executor = LocalExecutor()


@contextmanager
def executed_by(executor):
    """Within: every unit runs on `executor` (e.g. a Ray cluster), and so does every plain run of
    the batch engine (run_batch(seeds, p)) that the experiments make themselves."""
    global _executor
    before = _executor
    _executor = executor
    try:
        if isinstance(executor, LocalExecutor):
            yield executor
        else:
            with batch.distributed(distributed_batch):
                yield executor
    finally:
        _executor = before


def distributed_batch(seeds, p: Params) -> BatchResult:
    """run_batch(seeds, p) by the current executor: units small enough to keep its workers busy."""
    n_seeds = len(np.asarray(list(seeds)))
    return units_batch(p, seeds, "batch", block=min(SEED_BLOCK, -(-n_seeds // _executor.workers)))


def units_batch(p: Params, seeds, name: str, store: Path | None = None,
                block: int | None = SEED_BLOCK, log=None) -> BatchResult:
    """run_batch(seeds, p)'s result, run as units (run_units: on the current executor, kept in
    `store` when given); wall_s: the whole time, units read from the store included."""
    seeds = np.asarray(list(seeds), dtype=np.int64)
    start = time.perf_counter()
    arrays = run_units([(p, seeds)], name, store, block, log)[0]
    return BatchResult(seeds, arrays["initial_angles"], arrays["steps"], arrays["end_status"],
                       arrays["final_weights"], time.perf_counter() - start)


def run_units(jobs, name: str, store: Path | None = None, block: int | None = SEED_BLOCK,
              log=None, keep=UNIT_ARRAYS) -> list[dict]:
    """For each job (params, seeds) the batch engine's arrays (those of UNIT_ARRAYS in `keep`)
    of all its seeds, in their order. Each job is cut into units of `block` seeds (None: one
    unit); with a `store`, a unit stored there (under `name`) is read, not run, and each unit
    run is stored whole as soon as it is back; the others run on the current executor, a
    progress bar counting the finished units. log: a function given one line on what is stored
    and what is run where."""
    units, paths, owner = [], [], []
    for j, (p, seeds) in enumerate(jobs):
        seeds = np.asarray(list(seeds), dtype=np.int64)
        size = len(seeds) if block is None else block
        for first in range(0, len(seeds), size):
            part = seeds[first:first + size]
            units.append((p, part))
            owner.append(j)
            paths.append(None if store is None
                          else store_path(store, name, [p.to_dict(), part.tolist()]))
    results = [None if path is None else load_stored(path) for path in paths]
    results = [None if arrays is None else kept(arrays, keep) for arrays in results]
    missing = [k for k, arrays in enumerate(results) if arrays is None]
    if log is not None:
        log(f"{name}: {len(units)} units ({len(jobs)} configuration{'s' * (len(jobs) != 1)} x "
            f"blocks of up to {block or 'all'} seeds), {len(units) - len(missing)} stored, "
            f"{len(missing)} to run on {_executor.where}")
    with tqdm(total=len(units), initial=len(units) - len(missing), desc=name, unit="unit",
              leave=False, disable=None, file=sys.stderr) as bar:
        for i, arrays in _executor.run([units[k] for k in missing]):
            k = missing[i]
            if paths[k] is not None:
                store_arrays(paths[k], arrays)
            results[k] = kept(arrays, keep)
            bar.update(1)
    out = []
    for j in range(len(jobs)):
        mine = [results[k] for k in range(len(units)) if owner[k] == j]
        keys = [key for key in mine[0] if all(key in arrays for arrays in mine)]
        out.append({key: np.concatenate([arrays[key] for arrays in mine]) for key in keys})
    return out


def kept(arrays: dict, keep) -> dict:
    """The arrays named in `keep` (a run keeps what it needs; the store keeps them all)."""
    return {key: value for key, value in arrays.items() if key in keep}


def stored_batch(p: Params, seeds, store: Path, name: str) -> dict:
    """The batch engine's episodes (steps, end_status, final_weights, initial_angles) for p and
    seeds, one unit of all of them, or those stored for the same parameters and seeds by an
    earlier call."""
    return run_units([(p, seeds)], name, store, block=None)[0]
