"""What the experiments share: the paper's numbers, the run sizes, the velocity-edge scan, the
physics modes, the stuck threshold, and small helpers (seed specs, CSV, tables, progress bars, one
replayed trial)."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..batch import run_batch
from ..core.encoder import Encoder
from ..core.episode import run_trial
from ..core.params import Params
from ..core.physics import CartPole
from ..core.rln import RLNAgent, SuccessCounter

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
    states = [env.reset(angle_deg)]
    steps, status = run_trial(agent, SuccessCounter(p), env, Encoder.from_params(p), angle_deg, p,
                              learn=learn, trace=states.append)
    return np.array(states), steps, status


def stored(path: Path, compute) -> dict:
    """The arrays stored at `path`, or compute()'s (a dict of arrays) stored there first, written
    whole at once: an interrupted study or sweep resumes with what it finished."""
    if path.exists():
        with np.load(path) as data:
            return dict(data)
    arrays = compute()
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial.npz")
    np.savez_compressed(partial, **arrays)
    os.replace(partial, path)
    return arrays


def store_path(store: Path, name: str, key) -> Path:
    """Where a run named `name` is stored: the name made safe for a file, and a digest of `key`
    (what the run depends on, e.g. its parameters and seeds)."""
    safe = "".join(c if c.isalnum() else "_" for c in name)[:80]
    digest = hashlib.sha256(json.dumps(key, sort_keys=True, default=list).encode()).hexdigest()
    return store / f"{safe}_{digest[:16]}.npz"


def stored_batch(p: Params, seeds, store: Path, name: str) -> dict:
    """The batch engine's episodes (steps, end_status, final_weights) for p and seeds, or those
    stored for the same parameters and seeds by an earlier call."""
    seeds = np.asarray(list(seeds), dtype=np.int64)

    def learn():
        r = run_batch(seeds, p)
        return dict(steps=r.steps, end_status=r.end_status, final_weights=r.final_weights)

    return stored(store_path(store, name, [p.to_dict(), seeds.tolist()]), learn)
