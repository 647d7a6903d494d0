"""Reproduce Smith (2024): the paper's calibration numbers, the learning runs, Figures 7-15 and the
generated report docs/REPRODUCTION.md.

    python -m clnn_ros.reproduce calibrate [--out DIR]
    python -m clnn_ros.reproduce learn --nsv 1 --seeds 0-31 --trials 512 --out DIR [--option key=value]
    python -m clnn_ros.reproduce figures [--out DIR] [--seeds 0-31]
    python -m clnn_ros.reproduce all [--out docs]

Every run uses the numba batch engine (clnn_ros.batch) except the traces of Figures 10, 11 and 15,
which replay one trial with the pure core (clnn_ros.core.episode.run_trial, learn=False) on the
batch engine's final weights. All settings are the constants below.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .batch import BatchResult, evaluate_weights_batch, run_batch
from .cli import OneLineArgumentParser
from .core.encoder import Encoder
from .core.episode import angle_grid, run_episode, run_trial
from .core.gym_physics import GymCartPole, gym_matched_params
from .core.optimal import optimal_weights
from .core.params import ParamError, Params, params_from_strings
from .core.physics import CONTINUE, FAIL_POSITION, CartPole, cartpole_step, physics_constants
from .core.rln import RLNAgent, SuccessCounter

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
AMBIGUITY_SEEDS = "0-63"  # more seeds for the one-at-a-time option table (cheap with the batch engine)
TRIALS = 512  # trials per episode
LITERAL_EDGE = 5.0  # Table 1's velocity edge, m/s
EDGE_SCAN = tuple(float(e) for e in np.round(np.geomspace(0.05, 5.0, 25), 4))  # 0.05 .. 5, log-spaced
AMBIGUITY_EDGES = (0.1, 0.25, 0.5, 1.0, 2.0, 5.0)  # 2-SV learning at these edges (+ the scan's best)
MODES = (("paper", "semi_implicit"), ("paper", "euler"),
         ("correct", "semi_implicit"), ("correct", "euler"))  # physics x integrator
AMBIGUITY_OPTIONS = (  # each switched alone from the paper defaults
    ("tie_break", "index"), ("tie_break", "random"), ("tagging", "both_neurons"),
    ("e_flag", "live"), ("success_counter", "carry"), ("integrator", "euler"),
    ("physics", "correct"))
STUCK_BELOW = 1000  # a seed whose mean successful steps stay below this is "stuck"
NEAR_OPTIMAL = 0.8  # "nearly as well as optimal": seed mean >= this fraction of the optimal mean
FIG14_BETTER = 1.1  # Figure 14 bands, relative to the optimal 1-SV mean: better above 1.1x,
FIG14_WORSE = 0.8  # worse below 0.8x, "about the same" in between
MATCH_TOLERANCE = 0.05  # a number "matches" the paper within 5 %
SUCCESS_SECTION = (5000, 6000)  # steps shown for "a section of a successful trial" (Figs 11, 15)
END_REASONS = {0: "max_steps", 1: "pole_angle", 2: "cart_position"}  # physics status -> CSV text
COMMAND = "python -m clnn_ros.reproduce all"
GYM_SELECT_SEEDS = "32-63"  # gymnasium: the 2-SV velocity edge is chosen on these seeds ...
GYM_AGREE_SEEDS = (0, 1, 2, 3)  # ... and the core's physics checked against gymnasium's step
GYM_AGREE_LONG_TRIALS = 128  # trials compared where trials are long (pure-Python gymnasium)


# ------------------------------------------------------------------------------------------------
# Small helpers
# ------------------------------------------------------------------------------------------------
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
    return int(np.sum(means < STUCK_BELOW))


def write_csv(path: Path, header: list[str], rows) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def progress(items, desc: str):
    """A tqdm bar on stderr (hidden when stderr is not a terminal)."""
    return tqdm(items, desc=desc, leave=False, disable=None, file=sys.stderr)


def matches(measured: float, paper: float) -> bool:
    return abs(measured - paper) <= MATCH_TOLERANCE * abs(paper)


# ------------------------------------------------------------------------------------------------
# Calibration: the paper's numbers (a)-(d)
# ------------------------------------------------------------------------------------------------
def constant_force_trial(p: Params, force: float, angle_deg: float = 0.0) -> tuple[int, int]:
    """(successful steps, end status) under a constant force (N) from rest at `angle_deg`."""
    constants = physics_constants(p)
    x, x_dot, theta, theta_dot = 0.0, 0.0, float(angle_deg), 0.0
    for steps in range(p.max_steps):
        x, x_dot, theta, theta_dot, status = cartpole_step(x, x_dot, theta, theta_dot, force,
                                                           constants)
        if status != CONTINUE:
            return steps, status
    return p.max_steps, CONTINUE


def best_edge(edges, means) -> float:
    """The scan edge with the highest Figure 12 mean; on a plateau of equal means, its middle."""
    means = np.asarray(means)
    tied = [e for e, m in zip(edges, means) if m == means.max()]
    return float(tied[(len(tied) - 1) // 2])


def fig12_intervals_reversed(p: Params) -> list[int]:
    """Angle intervals (1-6) where the Figure 12 weights, seeing only the middle velocity interval
    (what the literal edge gives), choose the opposite action to the Figure 7 weights."""
    agent1, agent2 = RLNAgent(Params(nsv=1), optimal_weights(1)), RLNAgent(p, optimal_weights(2))
    reversed_ = []
    for a in range(6):
        s1, s2 = np.zeros(6, np.uint8), np.zeros(9, np.uint8)
        s1[a], s2[a], s2[7] = 1, 1, 1
        if agent1.infer(s1)[0] != agent2.infer(s2)[0]:
            reversed_.append(a + 1)
    return reversed_


def wrong_intervals(weights: np.ndarray, p: Params) -> list[int]:
    """Angle intervals (1-6) where 1-SV weights choose a different action from Figure 7's."""
    learned, optimal = RLNAgent(p, weights), RLNAgent(p, optimal_weights(1))
    wrong = []
    for a in range(6):
        spikes = np.zeros(6, np.uint8)
        spikes[a] = 1
        if learned.infer(spikes)[0] != optimal.infer(spikes)[0]:
            wrong.append(a + 1)
    return wrong


def velocity_ignored(weights: np.ndarray, p: Params) -> list[int]:
    """Angle intervals (1-6) where 2-SV weights choose the same action for all 3 velocity intervals."""
    agent = RLNAgent(p, weights)
    ignored = []
    for a in range(6):
        actions = set()
        for v in range(3):
            spikes = np.zeros(9, np.uint8)
            spikes[a], spikes[6 + v] = 1, 1
            actions.add(agent.infer(spikes)[0])
        if len(actions) == 1:
            ignored.append(a + 1)
    return ignored


def trace_trial(weights: np.ndarray, angle_deg: float, p: Params) -> tuple[np.ndarray, int, int]:
    """Replay one trial without learning through the core; (states (steps+1, 4), steps, status).
    Row 0 is the initial state, row k the state after step k."""
    states = [(0.0, 0.0, float(angle_deg), 0.0)]
    agent = RLNAgent(p, weights)
    steps, status = run_trial(agent, SuccessCounter(p), CartPole(p), Encoder.from_params(p),
                              angle_deg, p, learn=False, trace=states.append)
    return np.array(states), steps, status


def calibrate() -> dict:
    """Everything the paper's calibration numbers need, for every physics mode x integrator."""
    cal = {"grid": angle_grid(Params()), "modes": {}, "edges": np.array(EDGE_SCAN)}
    for physics, integrator in progress(MODES, "calibrate"):
        p1 = Params(nsv=1, physics=physics, integrator=integrator)
        p2 = p1.replace(nsv=2)
        no_force = np.array([constant_force_trial(p1, 0.0, a) for a in cal["grid"]])
        fig7 = evaluate_weights_batch(optimal_weights(1), p1)
        scan = [evaluate_weights_batch(optimal_weights(2), p2.replace(velocity_edge=e))
                for e in EDGE_SCAN]
        scan_steps = np.array([r.steps[0] for r in scan])
        cal["modes"][(physics, integrator)] = {
            "no_force_steps": no_force[:, 0], "no_force_status": no_force[:, 1],
            "plus": constant_force_trial(p1, +p1.force), "minus": constant_force_trial(p1, -p1.force),
            "fig7_steps": fig7.steps[0], "fig7_status": fig7.end_status[0],
            "fig12_steps": scan_steps, "fig12_status": np.array([r.end_status[0] for r in scan]),
            "best_edge": best_edge(EDGE_SCAN, scan_steps.mean(axis=1)),
        }
    paper = cal["modes"][("paper", "semi_implicit")]
    # (c) is chaotic in the start angle: the Figure 7 mean for angle grids equal to the paper's
    # up to rounding in the last bits.
    p1 = Params(nsv=1)
    grid = cal["grid"]
    variants = {"grid as in the core: -1.5 + 3k/31": grid,
                "numpy.linspace(-1.5, 1.5, 32)": np.linspace(-1.5, 1.5, 32),
                "grid + 1e-12 deg": grid + 1e-12,
                "grid - 1e-12 deg": grid - 1e-12,
                "grid rounded to float32": grid.astype(np.float32).astype(np.float64)}
    cal["fig7_sensitivity"] = {
        name: float(run_batch([0], p1, weights=optimal_weights(1), angles=a, learn=False).steps.mean())
        for name, a in variants.items()}
    # (d) at the literal edge: how fast the cart ever moves in those trials (paper physics).
    p2 = Params(nsv=2)
    max_speed = 0.0
    for angle in grid:
        states, _, _ = trace_trial(optimal_weights(2), angle, p2)
        max_speed = max(max_speed, float(np.abs(states[:, 1]).max()))
    cal["fig12_literal_max_speed"] = max_speed
    cal["fig12_reversed_intervals"] = fig12_intervals_reversed(p2)
    cal["best_edge"] = paper["best_edge"]
    return cal


def write_calibration(cal: dict, out: Path) -> list[Path]:
    grid, edges = cal["grid"], cal["edges"]
    no_force, forces, fig7, fig12, modes = [], [], [], [], []
    for (physics, integrator), m in cal["modes"].items():
        for a, s, st in zip(grid, m["no_force_steps"], m["no_force_status"]):
            no_force.append([physics, integrator, repr(float(a)), int(s), end_reason(st)])
        for name, (s, st) in (("+F", m["plus"]), ("-F", m["minus"])):
            forces.append([physics, integrator, name, int(s), end_reason(st)])
        for a, s, st in zip(grid, m["fig7_steps"], m["fig7_status"]):
            fig7.append([physics, integrator, repr(float(a)), int(s), end_reason(st)])
        for e, row_steps, row_status in zip(edges, m["fig12_steps"], m["fig12_status"]):
            for a, s, st in zip(grid, row_steps, row_status):
                fig12.append([physics, integrator, float(e), repr(float(a)), int(s), end_reason(st)])
        literal = list(edges).index(LITERAL_EDGE)
        best = list(edges).index(m["best_edge"])
        modes.append([physics, integrator, round(float(m["no_force_steps"].mean()), 2),
                      int(m["no_force_steps"][-1]), int(m["plus"][0]), end_reason(m["plus"][1]),
                      int(m["minus"][0]), end_reason(m["minus"][1]),
                      round(float(m["fig7_steps"].mean()), 2),
                      round(float(m["fig12_steps"][literal].mean()), 2), m["best_edge"],
                      round(float(m["fig12_steps"][best].mean()), 2)])
    angle_cols = ["physics", "integrator", "initial_angle_deg", "steps", "end_reason"]
    return [
        write_csv(out / "calib_no_force.csv", angle_cols, no_force),
        write_csv(out / "calib_constant_force.csv",
                  ["physics", "integrator", "force", "steps", "end_reason"], forces),
        write_csv(out / "calib_fig7.csv", angle_cols, fig7),
        write_csv(out / "calib_fig12_edge_scan.csv",
                  ["physics", "integrator", "velocity_edge", "initial_angle_deg", "steps",
                   "end_reason"], fig12),
        write_csv(out / "calib_summary.csv",
                  ["physics", "integrator", "a_no_force_mean", "a_no_force_from_1.5deg",
                   "b_plus_F_steps", "b_plus_F_end", "b_minus_F_steps", "b_minus_F_end",
                   "c_fig7_mean", "d_fig12_mean_literal_edge", "best_edge",
                   "d_fig12_mean_best_edge"], modes),
        write_csv(out / "calib_fig7_sensitivity.csv", ["angle_grid", "fig7_mean"],
                  [[k, v] for k, v in cal["fig7_sensitivity"].items()]),
    ]


def print_calibration(cal: dict) -> None:
    literal = list(cal["edges"]).index(LITERAL_EDGE)
    print(f"{'mode':22s} {'(a) mean':>8s} {'(a) 1.5':>7s} {'(b) +F':>18s} {'(b) -F':>18s} "
          f"{'(c) Fig7':>8s} {'(d) e=5':>8s} {'best e':>6s} {'(d) best':>8s}")
    for (physics, integrator), m in cal["modes"].items():
        best = list(cal["edges"]).index(m["best_edge"])
        print(f"{mode_label(physics, integrator):22s} {m['no_force_steps'].mean():8.1f} "
              f"{m['no_force_steps'][-1]:7d} "
              f"{m['plus'][0]:4d} {end_reason(m['plus'][1]):>13s} "
              f"{m['minus'][0]:4d} {end_reason(m['minus'][1]):>13s} "
              f"{m['fig7_steps'].mean():8.1f} {m['fig12_steps'][literal].mean():8.1f} "
              f"{m['best_edge']:6g} {m['fig12_steps'][best].mean():8.1f}")
    print(f"paper: (a) {PAPER['no_force_steps']}, (b) {PAPER['constant_force_steps']} by the cart, "
          f"(c) {PAPER['fig7_mean']}, (d) nearly all 32 angles reach 10,000")


# ------------------------------------------------------------------------------------------------
# Learning runs (batch engine)
# ------------------------------------------------------------------------------------------------
@dataclass
class Run:
    name: str  # file tag, e.g. "1sv" or "2sv_edge0.3406"
    label: str  # for titles and tables
    params: Params
    result: BatchResult

    @property
    def seed_means(self) -> np.ndarray:
        return self.result.steps.mean(axis=1)


def learn_run(name: str, label: str, seeds, p: Params) -> Run:
    return Run(name, label, p, run_batch(seeds, p))


def write_learn_outputs(run: Run, out: Path) -> list[Path]:
    """learn_<name>.csv (one row per trial), final_weights_<name>.npz and .csv."""
    r = run.result
    trial_rows = ([int(seed), trial, repr(float(r.initial_angles[k, trial])),
                   int(r.steps[k, trial]), end_reason(r.end_status[k, trial])]
                  for k, seed in enumerate(r.seeds) for trial in range(r.steps.shape[1]))
    weight_rows = ([int(seed), n, s, i, repr(float(r.final_weights[k, n, s, i]))]
                   for k, seed in enumerate(r.seeds) for n in range(2)
                   for s in range(r.final_weights.shape[2]) for i in range(r.final_weights.shape[3]))
    out.mkdir(parents=True, exist_ok=True)
    npz = out / f"final_weights_{run.name}.npz"
    np.savez_compressed(npz, seeds=r.seeds, final_weights=r.final_weights, steps=r.steps,
                        end_status=r.end_status, initial_angles=r.initial_angles,
                        params=json.dumps(run.params.to_dict()))
    return [write_csv(out / f"learn_{run.name}.csv",
                      ["seed", "trial", "initial_angle_deg", "steps", "end_reason"], trial_rows),
            npz,
            write_csv(out / f"final_weights_{run.name}.csv",
                      ["seed", "neuron", "segment", "input", "weight"], weight_rows)]


def print_seed_means(run: Run) -> None:
    r, means = run.result, run.seed_means
    print(f"{run.label}: {len(r.seeds)} seeds x {r.steps.shape[1]} trials "
          f"({r.wall_s:.1f} s in the batch engine)")
    print(f"{'seed':>6s} {'mean steps':>11s} {'trials at cap':>14s}")
    for seed, mean, capped in zip(r.seeds, means, (r.end_status == CONTINUE).sum(axis=1)):
        print(f"{seed:6d} {mean:11.1f} {capped:14d}")
    print(f"overall mean {means.mean():.1f}; seeds stuck below {STUCK_BELOW}: {stuck(means)}")


def main_runs(seeds, cal: dict) -> dict[str, Run]:
    """The paper's runs: 1 SV, 2 SV at the literal edge, 2 SV at the scan's best edge."""
    edge = cal["best_edge"]
    jobs = [("1sv", "1 SV", Params(nsv=1, trials=TRIALS)),
            ("2sv", f"2 SV, literal edge {LITERAL_EDGE:g}", Params(nsv=2, trials=TRIALS)),
            (f"2sv_edge{edge:g}", f"2 SV, scan's best edge {edge:g}",
             Params(nsv=2, trials=TRIALS, velocity_edge=edge))]
    runs = {}
    for name, label, p in progress(jobs, "learn"):
        runs[name] = learn_run(name, label, seeds, p)
    runs["2sv_best"] = runs[f"2sv_edge{edge:g}"]
    return runs


def physics_runs(seeds, cal: dict, runs: dict[str, Run]) -> dict:
    """Learning means (1 SV, 2 SV literal edge, 2 SV at that mode's best edge) for every mode."""
    table = {}
    for physics, integrator in progress(MODES, "physics modes"):
        base = Params(physics=physics, integrator=integrator, trials=TRIALS)
        edge = cal["modes"][(physics, integrator)]["best_edge"]
        if (physics, integrator) == ("paper", "semi_implicit"):
            means = [runs["1sv"].seed_means, runs["2sv"].seed_means, runs["2sv_best"].seed_means]
        else:
            means = [run_batch(seeds, base.replace(nsv=1)).steps.mean(axis=1),
                     run_batch(seeds, base.replace(nsv=2)).steps.mean(axis=1),
                     run_batch(seeds, base.replace(nsv=2, velocity_edge=edge)).steps.mean(axis=1)]
        table[(physics, integrator)] = {"edge": edge, "means": means}
    return table


def ambiguity(seeds, cal: dict) -> list[dict]:
    """Each open choice switched alone from the paper defaults; 1 SV, 2 SV literal and best edge."""
    edge = cal["best_edge"]
    configs = [("(paper defaults)", "", {})] + [(k, v, {k: v}) for k, v in AMBIGUITY_OPTIONS]
    jobs = [(name, value, nsv, e, change)
            for name, value, change in configs
            for nsv, e in ((1, LITERAL_EDGE), (2, LITERAL_EDGE), (2, edge))]
    jobs += [("velocity_edge", f"{e:g}", 2, e, {}) for e in sorted(set(AMBIGUITY_EDGES) | {edge})]
    rows, done = [], {}
    for name, value, nsv, e, change in progress(jobs, "ambiguity"):
        p = Params(nsv=nsv, velocity_edge=e, trials=TRIALS, **change)
        if p not in done:  # the edge rows at 5 and the best edge repeat the defaults' runs
            done[p] = run_batch(seeds, p).steps.mean(axis=1)
        means = done[p]
        rows.append({"option": name, "value": value, "nsv": nsv, "velocity_edge": e,
                     "seeds": np.asarray(seeds), "means": means})
        if name == "velocity_edge":  # and the Figure 12 weights at that edge, for comparison
            rows[-1]["fig12_mean"] = float(evaluate_weights_batch(optimal_weights(2), p).steps.mean())
    return rows


def write_ambiguity(rows: list[dict], out: Path) -> list[Path]:
    summary = [[r["option"], r["value"], r["nsv"], r["velocity_edge"], len(r["seeds"]),
                round(float(r["means"].mean()), 2), stuck(r["means"])] for r in rows]
    per_seed = [[r["option"], r["value"], r["nsv"], r["velocity_edge"], int(s), round(float(m), 3)]
                for r in rows for s, m in zip(r["seeds"], r["means"])]
    return [write_csv(out / "ambiguity.csv", ["option", "value", "nsv", "velocity_edge", "seeds",
                                              "mean_steps", f"seeds_below_{STUCK_BELOW}"], summary),
            write_csv(out / "ambiguity_per_seed.csv",
                      ["option", "value", "nsv", "velocity_edge", "seed", "mean_steps"], per_seed)]


def write_physics(table: dict, cal: dict, out: Path) -> Path:
    rows = []
    for (physics, integrator), entry in table.items():
        rows.append([physics, integrator, entry["edge"]]
                    + [round(float(m.mean()), 2) for m in entry["means"]]
                    + [stuck(m) for m in entry["means"]])
    return write_csv(out / "physics_modes_learning.csv",
                     ["physics", "integrator", "best_edge", "learn_1sv_mean",
                      "learn_2sv_literal_edge_mean", "learn_2sv_best_edge_mean", "stuck_1sv",
                      "stuck_2sv_literal_edge", "stuck_2sv_best_edge"], rows)


# ------------------------------------------------------------------------------------------------
# Traces (Figures 10, 11, 15): the core replays one trial on learned weights
# ------------------------------------------------------------------------------------------------
def pick_trace(run: Run, want: str) -> dict | None:
    """A typical trial after learning: seeds are tried from the one whose mean is closest to the
    median seed mean outwards; the seed's final weights are evaluated on the 32 grid angles
    (batch engine) and the trial wanted ("cart" = failed by the cart, "cap" = reached the cap)
    with the median step count among those is replayed through the core."""
    means = run.seed_means
    order = np.argsort(np.abs(means - np.median(means)), kind="stable")
    for k in order:
        weights = run.result.final_weights[k]
        ev = evaluate_weights_batch(weights, run.params)
        steps, status = ev.steps[0], ev.end_status[0]
        ok = status == (FAIL_POSITION if want == "cart" else CONTINUE)
        if not ok.any():
            continue
        candidates = np.flatnonzero(ok)
        pick = candidates[np.argsort(steps[candidates], kind="stable")[len(candidates) // 2]]
        angle = float(ev.initial_angles[0, pick])
        p = run.params
        if want == "cap":  # only the section is plotted
            p = p.replace(max_steps=min(p.max_steps, SUCCESS_SECTION[1]))
        states, n, st = trace_trial(weights, angle, p)
        first = 0
        if want == "cap":
            first = max(0, min(SUCCESS_SECTION[0], len(states) - 1))
            states = states[first:]
        return {"seed": int(run.result.seeds[k]), "seed_mean": float(means[k]), "angle": angle,
                "weights": weights, "params": run.params,
                "steps": int(steps[pick]), "status": int(status[pick]), "states": states,
                "first": first, "replayed_steps": n, "replayed_status": st}
    return None


# ------------------------------------------------------------------------------------------------
# Figures
# ------------------------------------------------------------------------------------------------
def make_figures(cal: dict, runs: dict[str, Run], out: Path) -> dict:
    """Figures 7-15 (plus the edge scan and learning curves) as PNGs in `out`; returns their paths
    and the traces used."""
    from . import figures as F

    out.mkdir(parents=True, exist_ok=True)
    paper_mode = cal["modes"][("paper", "semi_implicit")]
    grid, edges = cal["grid"], list(cal["edges"])
    literal, best = edges.index(LITERAL_EDGE), edges.index(cal["best_edge"])
    opt1 = float(paper_mode["fig7_steps"].mean())
    opt2 = {LITERAL_EDGE: float(paper_mode["fig12_steps"][literal].mean()),
            cal["best_edge"]: float(paper_mode["fig12_steps"][best].mean())}
    max_steps = Params().max_steps
    paths, traces = {}, {}
    jobs = []

    jobs.append(("fig07", lambda p: F.plot_weights(optimal_weights(1), p,
                                                   "Figure 7: optimal weights, 1 SV")))
    jobs.append(("fig12", lambda p: F.plot_weights(optimal_weights(2), p,
                                                   "Figure 12: optimal weights, 2 SV")))
    jobs.append(("fig08", lambda p: F.plot_steps_per_angle(
        [("paper physics, semi-implicit Euler", grid, paper_mode["fig7_steps"],
          paper_mode["fig7_status"], {"paper's mean": PAPER["fig7_mean"]})], p,
        "Figure 8: steps per initial angle, Figure 7 weights (1 SV)", max_steps)))
    jobs.append(("fig13", lambda p: F.plot_steps_per_angle(
        [(f"velocity edge {e:g} m/s" + (" (Table 1, literal)" if e == LITERAL_EDGE
                                         else " (best of the scan)"),
          grid, paper_mode["fig12_steps"][edges.index(e)], paper_mode["fig12_status"][edges.index(e)],
          {}) for e in (LITERAL_EDGE, cal["best_edge"])], p,
        "Figure 13: steps per initial angle, Figure 12 weights (2 SV)", max_steps)))
    jobs.append(("edge_scan", lambda p: F.plot_edge_scan(
        np.array(edges), {mode_label(*k): m["fig12_steps"].mean(axis=1)
                          for k, m in cal["modes"].items()}, p,
        "Figure 12 weights vs the velocity edge", {"literal (Table 1)": LITERAL_EDGE,
                                                   "best (paper/semi_implicit)": cal["best_edge"]},
        max_steps)))
    one = runs["1sv"]
    jobs.append(("fig09", lambda p: F.plot_seed_means(
        one.result.seeds, one.seed_means, p,
        f"Figure 9: 1 SV, mean steps over {one.result.steps.shape[1]} trials per seed",
        {"optimal 1 SV (Figure 7)": opt1, "mean of the seeds": float(one.seed_means.mean())},
        max_steps=max_steps)))
    for key in ("1sv", "2sv", "2sv_best"):
        run = runs[key]
        lines = {"optimal 1 SV": opt1}
        if run.params.nsv == 2:
            lines[f"optimal 2 SV, edge {run.params.velocity_edge:g}"] = opt2[run.params.velocity_edge]
        jobs.append((f"learning_curves_{run.name}", lambda p, run=run, lines=lines:
                     F.plot_learning_curves(run.result.steps, p,
                                            f"Learning curves, {run.label}", lines, max_steps)))
    for key, tag in (("2sv", "literal_edge"), ("2sv_best", "best_edge")):
        run = runs[key]
        e = run.params.velocity_edge
        jobs.append((f"fig14_{tag}", lambda p, run=run, e=e: F.plot_seed_means(
            run.result.seeds, run.seed_means, p, f"Figure 14: {run.label}, seeds sorted",
            {"optimal 1 SV": opt1, f"optimal 2 SV (edge {e:g})": opt2[e],
             "1 SV learned, mean of the seeds": float(one.seed_means.mean())},
            sort=True, max_steps=max_steps)))

    for name, plot in progress(jobs, "figures"):
        paths[name] = plot(out / f"{name}.png")

    limits = (Params().angle_limit_deg, Params().track_limit_m)
    trace_jobs = (("fig10", runs["1sv"], "cart", "Figure 10: a typical failing trial"),
                  ("fig11", runs["1sv"], "cap", "Figure 11: a section of a successful trial"),
                  ("fig15", runs["2sv_best"], "cap", "Figure 15: a section of a successful trial"))
    for name, run, want, title in progress(trace_jobs, "traces"):
        t = pick_trace(run, want)
        if t is None and name == "fig15":  # no capped trial at the best edge: try the literal edge
            run = runs["2sv"]
            t = pick_trace(run, want)
        traces[name] = t
        if t is None:
            continue
        t["run"] = run.label
        detail = (f"{run.label}; seed {t['seed']} (episode mean {t['seed_mean']:.0f}), final weights, "
                  f"no learning; start {t['angle']:+.3f} deg; {t['steps']} steps, "
                  f"{END_REASONS[t['status']].replace('_', ' ')}")
        paths[name] = F.plot_trace(t["states"], t["first"], out / f"{name}.png",
                                   f"{title}\n{detail}", *limits)
    return {"paths": paths, "traces": traces}


# ------------------------------------------------------------------------------------------------
# The report (docs/REPRODUCTION.md)
# ------------------------------------------------------------------------------------------------
def fig14_counts(means: np.ndarray, opt1: float) -> tuple[int, int, int]:
    better = int(np.sum(means > FIG14_BETTER * opt1))
    worse = int(np.sum(means < FIG14_WORSE * opt1))
    return better, len(means) - better - worse, worse


def _f(x: float) -> str:
    return f"{x:,.0f}"


def claims_table(cal: dict, runs: dict[str, Run]) -> list[tuple[str, str, str, str]]:
    """(claim, paper, measured, why it differs) rows, all numbers from the measurements."""
    pm = cal["modes"][("paper", "semi_implicit")]
    grid, edges = cal["grid"], list(cal["edges"])
    literal, best_i = edges.index(LITERAL_EDGE), edges.index(cal["best_edge"])
    rows = []

    # (a)
    nf = pm["no_force_steps"]
    closest = int(np.argmin(np.abs(nf - PAPER["no_force_steps"])))
    measured = (f"mean {nf.mean():.0f} over the 32 grid angles (range {nf.min()}-{nf.max()}); "
                f"from {grid[-1]:g}°: {nf[-1]}; closest grid angle: {grid[closest]:+.3f}° → "
                f"{nf[closest]}")
    why = ("matches within 5 %" if matches(nf.mean(), PAPER["no_force_steps"]) else "differs") + \
        "; the paper does not state the start angle, and the fall time depends on it (not tuned)"
    rows.append(("(a) no force: pole falls after", str(PAPER["no_force_steps"]), measured, why))

    # (b)
    plus, minus = pm["plus"], pm["minus"]
    ok = plus[0] == minus[0] == PAPER["constant_force_steps"] and plus[1] == minus[1] == FAIL_POSITION
    rows.append(("(b) constant ±F: cart leaves the track after", f"{PAPER['constant_force_steps']}",
                 f"+F: {plus[0]} ({end_reason(plus[1])}), −F: {minus[0]} ({end_reason(minus[1])})",
                 "matches exactly" if ok else "differs"))

    # (c)
    f7 = pm["fig7_steps"]
    sens = cal["fig7_sensitivity"]
    spread = f"{min(sens.values()):,.0f}-{max(sens.values()):,.0f}"
    why = "matches within 5 %" if matches(f7.mean(), PAPER["fig7_mean"]) else (
        f"chaotic in the start angle: grids equal to ours up to the last bits give means {spread} "
        f"(see the sensitivity table below); the paper's exact angle values are unknown")
    reasons = {END_REASONS[c]: int(np.sum(pm["fig7_status"] == c)) for c in END_REASONS}
    rows.append(("(c) Figure 7 weights, mean over 32 angles", _f(PAPER["fig7_mean"]),
                 f"{f7.mean():,.0f} (ends: " + ", ".join(f"{k} {v}" for k, v in reasons.items())
                 + ")", why))

    # Figure 8 pattern
    capped = pm["fig7_status"] == CONTINUE
    rest = f7[~capped]
    cap_angles = np.abs(grid[capped])
    measured = (f"{capped.sum()} of 32 reach 10,000"
                + (f" (|θ0| from {cap_angles.min():.2f}° to {cap_angles.max():.2f}°)" if capped.any() else "")
                + (f"; the others {rest.min():,}-{rest.max():,}, "
                   f"{int(np.sum(pm['fig7_status'] == FAIL_POSITION))} by the cart" if len(rest) else ""))
    inside = len(rest) and rest.min() >= PAPER["fig8_low"] * (1 - MATCH_TOLERANCE) and \
        rest.max() <= PAPER["fig8_high"] * (1 + MATCH_TOLERANCE)
    near_zero = capped.any() and np.abs(grid[capped]).min() <= np.abs(grid).min()
    rows.append(("Figure 8: angles near 0 reach 10,000, the others 3,000-9,000",
                 "near 0: 10,000; others 3,000-9,000",
                 measured,
                 "same pattern" if inside and near_zero else
                 "pattern differs in detail: which angles reach the cap is chaotic in the start "
                 "angle, as for (c)"))

    # (d)
    for e_i, what in ((literal, f"literal edge {LITERAL_EDGE:g}"), (best_i, f"scan's best edge {cal['best_edge']:g}")):
        s = pm["fig12_steps"][e_i]
        n_cap = int(np.sum(pm["fig12_status"][e_i] == CONTINUE))
        if e_i == literal:
            why = (f"|dx/dt| stays below {cal['fig12_literal_max_speed']:.2f} m/s in these trials, so the "
                   f"velocity input never leaves the middle interval; the Figure 12 rows for that "
                   f"interval push the opposite way to Figure 7 in angle interval(s) "
                   f"{', '.join(map(str, cal['fig12_reversed_intervals']))}; trials end by: "
                   + ", ".join(f"{END_REASONS[c]} {n}" for c, n in
                               zip(*np.unique(pm["fig12_status"][e_i], return_counts=True))))
            if n_cap >= 30:
                why = "matches"
        else:
            plateau = [e for e, m in zip(edges, pm["fig12_steps"].mean(axis=1))
                       if m == pm["fig12_steps"][best_i].mean()]
            why = (f"matches for edges {min(plateau):g}-{max(plateau):g} m/s (the scan's best; "
                   f"the middle of that range is used)" if n_cap >= 30 else "differs")
        rows.append((f"(d)/Figure 13: Figure 12 weights, {what}", "nearly all 32 reach 10,000",
                     f"{n_cap} of 32 reach 10,000, mean {s.mean():,.0f}", why))

    # Figure 9 and "nearly as well as optimal"
    one = runs["1sv"]
    means = one.seed_means
    opt1 = float(f7.mean())
    late = one.result.steps[:, one.result.steps.shape[1] // 2:].mean(axis=1)
    rows.append(("Figure 9: 1 SV learned, mean and spread over 32 seeds", "figure only (no number in the text)",
                 f"mean {means.mean():,.0f}, median {np.median(means):,.0f}, "
                 f"range {means.min():,.0f}-{means.max():,.0f}, std {means.std():,.0f}; "
                 f"{stuck(means)} of {len(means)} seeds below {STUCK_BELOW:,}", ""))
    near = int(np.sum(means >= NEAR_OPTIMAL * opt1))
    good = means >= NEAR_OPTIMAL * opt1
    rows.append(("1 SV learned performs nearly as well as optimal (gap = early untrained trials)",
                 "nearly as well as optimal",
                 f"mean = {means.mean() / opt1:.0%} of optimal ({opt1:,.0f}); {near} of {len(means)} seeds "
                 f"≥ {NEAR_OPTIMAL:.0%} of optimal; 2nd-half trials of those seeds: "
                 f"{(late[good].mean() / opt1 if good.any() else 0):.0%} of optimal",
                 ("holds for most seeds; the stuck seeds end with the wrong action (vs Figure 7) "
                  "in angle interval(s): " + "; ".join(
                      f"seed {seed}: {', '.join(map(str, wrong_intervals(w, one.params))) or 'none'}"
                      for seed, w, m in zip(one.result.seeds, one.result.final_weights, means)
                      if m < STUCK_BELOW)) if stuck(means) else "holds"))

    # Figure 10: failures by the cart
    status = one.result.end_status
    failed = status != CONTINUE
    late_status = status[:, status.shape[1] // 2:]
    late_failed = late_status != CONTINUE
    by_cart = float(np.sum(status == FAIL_POSITION) / max(failed.sum(), 1))
    late_cart = float(np.sum(late_status == FAIL_POSITION) / max(late_failed.sum(), 1))
    rows.append(("Figure 10: failures are typically by the cart (slow drift)", "typically the cart",
                 f"{by_cart:.0%} of all {failed.sum():,} failed 1-SV trials end by the cart; "
                 f"{late_cart:.0%} in the 2nd half of the episodes",
                 "holds" if late_cart >= 0.5 else "differs: early trials fail by the pole while "
                 "the network is untrained; see the stuck seeds"))

    # Figure 14
    for key in ("2sv", "2sv_best"):
        run = runs[key]
        b, s, w = fig14_counts(run.seed_means, opt1)
        e = run.params.velocity_edge
        if e == LITERAL_EDGE:
            why = (f"at this edge the velocity input stays in its middle interval in ordinary "
                   f"balancing (see (d)), so 2 SV acts like 1 SV with 9 segments per neuron: "
                   f"{stuck(run.seed_means)} seeds stuck vs {stuck(means)} for 1 SV")
        else:
            why = (f"{stuck(run.seed_means)} of {len(run.seed_means)} seeds stuck below "
                   f"{STUCK_BELOW:,}: with the velocity input active, learning often locks into "
                   "a poor local optimum")
        rows.append((f"Figure 14: learned {run.label}",
                     f"{PAPER['fig14_better']} clearly better, {PAPER['fig14_same']} about the same, "
                     f"about half ({PAPER['fig14_worse']}) worse than 1 SV",
                     f"{b} better, {s} about the same, {w} worse; mean {run.seed_means.mean():,.0f}",
                     why))
    return rows


def _md_table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |" for row in rows]
    return "\n".join(lines)


def write_report(path: Path, cal: dict, runs: dict[str, Run], physics: dict, amb: list[dict],
                 figs: dict, seeds, amb_seeds, runtime_s: float, data_files: list[Path],
                 seed_spec: str, amb_spec: str, extra_sections: list[str] = ()) -> Path:
    """docs/REPRODUCTION.md: every number in it comes from the arguments."""
    pm = cal["modes"][("paper", "semi_implicit")]
    rel = lambda p: os.path.relpath(p, path.parent)  # noqa: E731
    opt1 = float(pm["fig7_steps"].mean())
    md = []
    md.append("# Reproduction report: Smith (2024), online RL with clustering neural networks\n")
    md.append(f"> **Generated** by `{COMMAND}` (clnn_ros/reproduce.py). Do not edit by hand: every "
              f"number below is measured by that command. Runtime {runtime_s:.0f} s on "
              f"{os.cpu_count()} CPU cores. {len(seeds)} seeds ({seed_spec}) for the "
              f"paper's runs, {len(amb_seeds)} seeds ({amb_spec}) for the option table; {TRIALS} trials per "
              f"episode.\n")
    md.append("Conventions: the project's `paper` defaults (`clnn_ros.core.params.Params`, see "
              "the module docstrings and the conventions note): paper physics (θ̈ too small by "
              "180/π), semi-implicit Euler, ties broken by exact sums, only the action path tagged, "
              "e flag latched, success counter reset per trial, seed protocol "
              "`numpy.random.default_rng(seed)`. Every run except the three traces uses the numba "
              "batch engine (`clnn_ros.batch`), which is tested equal to the pure core trial by "
              "trial. Thresholds used below: a seed is *stuck* when its mean is below "
              f"{STUCK_BELOW:,} steps; Figure 14 bands are relative to the optimal 1-SV mean "
              f"({opt1:,.0f}): better above {FIG14_BETTER:g}×, worse below {FIG14_WORSE:g}×.\n")

    md.append("## Paper vs measured\n")
    md.append(_md_table(["claim", "paper", "measured", "why it differs / note"],
                        [list(r) for r in claims_table(cal, runs)]) + "\n")
    md.append("Sensitivity of (c) to the start angles (Figure 7 weights, paper physics):\n")
    md.append(_md_table(["angle grid", "mean steps"],
                        [[k, f"{v:,.1f}"] for k, v in cal["fig7_sensitivity"].items()]) + "\n")

    md.append("## Figures\n")
    captions = {
        "fig07": "Figure 7: optimal weights, 1 SV (from `clnn_ros.core.optimal`).",
        "fig12": "Figure 12: optimal weights, 2 SV.",
        "fig08": "Figure 8: steps per initial angle with the Figure 7 weights.",
        "fig13": "Figure 13: steps per initial angle with the Figure 12 weights, literal edge and "
                 "the scan's best edge.",
        "edge_scan": "Figure 12 weights: mean steps against the velocity edge, all physics modes.",
        "fig09": "Figure 9: per-seed mean steps, 1 SV learned, with the optimal line.",
        "learning_curves_1sv": "Learning curves, 1 SV (each seed faint, mean bold).",
        "learning_curves_2sv": "Learning curves, 2 SV at the literal edge.",
        f"learning_curves_{runs['2sv_best'].name}": "Learning curves, 2 SV at the scan's best edge.",
        "fig10": "Figure 10: a typical failing 1-SV trial (final weights of a median seed, replayed "
                 "without learning).",
        "fig11": f"Figure 11: steps {SUCCESS_SECTION[0]}-{SUCCESS_SECTION[1]} of a successful 1-SV trial.",
        "fig14_literal_edge": "Figure 14: 2-SV per-seed means, sorted, literal edge.",
        "fig14_best_edge": "Figure 14: 2-SV per-seed means, sorted, the scan's best edge.",
        "fig15": f"Figure 15: steps {SUCCESS_SECTION[0]}-{SUCCESS_SECTION[1]} of a successful 2-SV trial.",
    }
    t15 = figs["traces"].get("fig15")
    if t15 is not None:
        ignored = velocity_ignored(t15["weights"], t15["params"])
        captions["fig15"] += (" In this seed's learned weights the action does not depend on the "
                              "velocity input in angle interval(s) "
                              f"{', '.join(map(str, ignored)) or 'none'}"
                              + (", the only ones this oscillation visits, so it moves like a 1-SV "
                                 "trial." if {3, 4} <= set(ignored)
                                 and np.abs(t15["states"][:, 2]).max() < 1.0 else "."))
    for name, caption in captions.items():
        if name in figs["paths"]:
            md.append(f"**{caption}**\n\n![{name}]({rel(figs['paths'][name])})\n")
        else:
            md.append(f"**{caption}** Not drawn: no such trial in these runs.\n")

    md.append("## Paper physics vs correct physics\n")
    md.append("`paper` computes θ̈ in rad/s² and adds it to θ̇ in deg/s (too small by 180/π); "
              "`correct` uses consistent units (Gymnasium-equivalent). Each is run with both "
              "integrators. (a) is the no-force fall (mean over the 32 grid angles, and from "
              "1.5°), (b) constant ±F from 0, (c) the Figure 7 mean, (d) the Figure 12 mean at the "
              "literal edge and at that mode's best scan edge.\n")
    edges = list(cal["edges"])
    rows = []
    for (ph, integ), m in cal["modes"].items():
        lit, b = edges.index(LITERAL_EDGE), edges.index(m["best_edge"])
        rows.append([mode_label(ph, integ), f"{m['no_force_steps'].mean():.0f}",
                     str(m["no_force_steps"][-1]),
                     f"{m['plus'][0]} ({end_reason(m['plus'][1])}) / {m['minus'][0]} "
                     f"({end_reason(m['minus'][1])})",
                     f"{m['fig7_steps'].mean():,.0f}", f"{m['fig12_steps'][lit].mean():,.0f}",
                     f"{m['fig12_steps'][b].mean():,.0f} (edge {m['best_edge']:g})"])
    md.append(_md_table(["mode", "(a) mean", "(a) from 1.5°", "(b) +F / −F", "(c) Fig 7",
                         "(d) Fig 12 literal", "(d) Fig 12 best"], rows) + "\n")
    fits = [mode_label(*k) for k, m in cal["modes"].items()
            if m["plus"][0] == m["minus"][0] == PAPER["constant_force_steps"]
            and m["plus"][1] == m["minus"][1] == FAIL_POSITION
            and abs(m["no_force_steps"].mean() - PAPER["no_force_steps"])
            <= 2 * MATCH_TOLERANCE * PAPER["no_force_steps"]]
    md.append(f"Modes where (b) is exactly the paper's {PAPER['constant_force_steps']} (by the cart) "
              f"and (a) is within {2 * MATCH_TOLERANCE:.0%} of its {PAPER['no_force_steps']}: "
              + (", ".join(fits) if fits else "none") + ".\n")
    md.append(f"Learned means over {len(seeds)} seeds in each mode (seeds below {STUCK_BELOW:,} in "
              "brackets):\n")
    rows = []
    for (ph, integ), entry in physics.items():
        cells = [f"{m.mean():,.0f} ({stuck(m)})" for m in entry["means"]]
        rows.append([mode_label(ph, integ), *cells[:2], f"{cells[2]} at edge {entry['edge']:g}"])
    md.append(_md_table(["mode", "learned 1 SV", "learned 2 SV, literal edge",
                         "learned 2 SV, mode's best edge"], rows) + "\n")

    md.append("## Open choices, one at a time\n")
    md.append(f"Each row switches one option from the paper defaults; {len(amb_seeds)} seeds "
              f"× {TRIALS} trials; cells are the mean over seeds of the per-seed mean steps, with "
              f"the number of seeds below {STUCK_BELOW:,} in brackets.\n")
    best = cal["best_edge"]
    table = {}
    for r in amb:
        if r["option"] == "velocity_edge":
            continue
        key = (r["option"], r["value"])
        col = 0 if r["nsv"] == 1 else (1 if r["velocity_edge"] == LITERAL_EDGE else 2)
        table.setdefault(key, ["", "", ""])[col] = f"{r['means'].mean():,.0f} ({stuck(r['means'])})"
    md.append(_md_table(["option", "value", "1 SV", f"2 SV, edge {LITERAL_EDGE:g}",
                         f"2 SV, edge {best:g}"],
                        [[k[0], k[1] or "—", *v] for k, v in table.items()]) + "\n")
    rows = [[f"{r['velocity_edge']:g}", f"{r['fig12_mean']:,.0f}", f"{r['means'].mean():,.0f}",
             str(stuck(r["means"]))] for r in amb if r["option"] == "velocity_edge"]
    md.append("2 SV against the velocity edge (paper defaults otherwise):\n")
    md.append(_md_table(["velocity edge (m/s)", "Figure 12 weights mean", "learned mean",
                         f"seeds below {STUCK_BELOW:,}"], rows) + "\n")

    md.append("## Data files\n")
    md.append("All in `" + os.path.relpath(data_files[0].parent, path.parent) + "/`: "
              + ", ".join(f"`{p.name}`" for p in data_files) + ". Per-trial CSVs have columns "
              "seed, trial, initial_angle_deg, steps, end_reason (max_steps, pole_angle, "
              "cart_position); final-weight CSVs seed, neuron (0 = −F, 1 = +F), segment, input "
              "(0-based: angle intervals, then velocity intervals), weight.\n")
    md.extend(extra_sections)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(md))
    return path


# ------------------------------------------------------------------------------------------------
# Gymnasium's CartPole-v1 physics (docs/ENV_CONTRACT.md): the batch engine with gymnasium's
# constants, checked trial by trial against the core driving gymnasium's own step
# ------------------------------------------------------------------------------------------------
def gymnasium_study(seeds, select_seeds) -> dict:
    base = gym_matched_params(Params(trials=TRIALS))
    scan = [float(run_batch(select_seeds, base.replace(nsv=2, velocity_edge=e)).steps.mean())
            for e in progress(EDGE_SCAN, "gymnasium edge scan")]
    edge = float(EDGE_SCAN[int(np.argmax(scan))])
    configs = [("1sv", "1 SV", base.replace(nsv=1), TRIALS),
               ("2sv", f"2 SV, literal edge {LITERAL_EDGE:g}", base.replace(nsv=2), TRIALS),
               ("2sv_best", f"2 SV, edge {edge:g}", base.replace(nsv=2, velocity_edge=edge),
                GYM_AGREE_LONG_TRIALS)]
    learn, agree = {}, []
    for key, label, p, agree_trials in progress(configs, "gymnasium"):
        learn[key] = (label, run_batch(seeds, p).steps)
        # the same episodes' first trials: core's physics (batch) vs gymnasium's step (core)
        own = run_batch(GYM_AGREE_SEEDS, p.replace(trials=agree_trials)).steps
        for k, seed in enumerate(GYM_AGREE_SEEDS):  # GymCartPole ignores p's physics
            gym = run_episode(seed, p.replace(trials=agree_trials), env_factory=GymCartPole).steps
            same = gym == own[k]
            agree.append({"config": label, "seed": seed, "trials": agree_trials,
                          "equal": int(same.sum()),
                          "first_diff": "" if same.all() else int(np.argmin(same)),
                          "gym_mean": float(gym.mean()), "own_mean": float(own[k].mean()),
                          "longest_equal": int(gym[same].max(initial=0)),
                          "gym_max": int(gym.max())})
    return {"edge": edge, "scan": scan, "learn": learn, "agree": agree,
            "seeds": np.asarray(seeds), "select_seeds": np.asarray(select_seeds)}


def write_gymnasium(gym: dict, out: Path) -> list[Path]:
    per_seed = [[label, int(s), round(float(m), 3)] for label, steps in gym["learn"].values()
                for s, m in zip(gym["seeds"], steps.mean(axis=1))]
    agree = [[a["config"], a["seed"], a["trials"], a["equal"], a["first_diff"],
              round(a["gym_mean"], 2), round(a["own_mean"], 2)] for a in gym["agree"]]
    return [write_csv(out / "gym_learning_per_seed.csv", ["config", "seed", "mean_steps"], per_seed),
            write_csv(out / "gym_edge_scan.csv", ["velocity_edge", "mean_steps"],
                      [[e, round(m, 2)] for e, m in zip(EDGE_SCAN, gym["scan"])]),
            write_csv(out / "gym_agreement.csv", ["config", "seed", "trials", "equal_trials",
                                                  "first_differing_trial", "gymnasium_mean",
                                                  "core_physics_mean"], agree)]


def gymnasium_markdown(gym: dict, runs: dict[str, Run], physics: dict, files: list[Path],
                       rel) -> str:
    md = ["## Gymnasium's physics (CartPole-v1)\n"]
    md.append("The unchanged agent against gymnasium's `CartPole-v1` physics (`python -m "
              "clnn_ros.run_all --env gymnasium`, docs/ENV_CONTRACT.md): cart 1.0 kg, pole 0.1 kg, "
              "half-length 0.5 m, force 10 N, tau 0.02 s, explicit Euler, correct units, the same "
              "limits (12 deg = 0.2095 rad, 2.4 m). The runs below use the batch engine with these "
              "constants (`gym_matched_params`: physics `correct`, integrator `euler`); the ROS "
              "node and `run_episode(..., env_factory=GymCartPole)` step gymnasium itself, and a "
              "node run equals that core run trial by trial (tests/test_env_contract.py).\n")
    md.append(f"**Same physics?** The batch engine (the core's own step, degrees) against the core "
              f"driving gymnasium's step (radians), seeds {', '.join(map(str, GYM_AGREE_SEEDS))}, "
              "the first trials of the same episodes:\n")
    rows = [[a["config"], a["seed"], f"{a['equal']}/{a['trials']}",
             "—" if a["first_diff"] == "" else a["first_diff"], f"{a['gym_mean']:,.1f}",
             f"{a['own_mean']:,.1f}", f"{a['longest_equal']:,}", f"{a['gym_max']:,}"]
            for a in gym["agree"]]
    md.append(_md_table(["config", "seed", "identical trials", "first differing trial",
                         "gymnasium mean", "core physics mean", "longest identical trial",
                         "longest gymnasium trial"], rows) + "\n")
    diverged = [a for a in gym["agree"] if a["first_diff"] != ""]
    md.append("Both compute the same equations, but in different units and operation order, so "
              "their states differ in the last bits. While trials are short the actions never "
              "differ and the episodes are identical; " + (
                  f"in {len(diverged)} of {len(gym['agree'])} episodes a long balancing trial "
                  "amplified the rounding difference into a different action (the cart-pole "
                  "under bang-bang control is chaotic), and from there the two episodes go "
                  "their own ways, with similar means. The batch numbers below are therefore "
                  "gymnasium's physics statistically, not trial by trial."
                  if diverged else "no episode diverged.") + "\n")
    paper = {"1sv": runs["1sv"].seed_means, "2sv": runs["2sv"].seed_means,
             "2sv_best": runs["2sv_best"].seed_means}
    ce = physics.get(("correct", "euler"))
    rows = []
    for i, (key, (label, steps)) in enumerate(gym["learn"].items()):
        means = steps.mean(axis=1)
        cells = [label, f"{means.mean():,.0f} ({stuck(means)})", f"{np.median(means):,.0f}",
                 f"{steps[:, -64:].mean():,.0f}", f"{np.mean(steps == 10_000):.1%}",
                 f"{paper[key].mean():,.0f} ({stuck(paper[key])})"]
        if ce is not None:
            cells.append(f"{ce['means'][i].mean():,.0f} ({stuck(ce['means'][i])})")
        rows.append(cells)
    header = ["encoding", "gymnasium: mean (stuck)", "median seed mean", "mean of the last 64 trials",
              "trials at the 10,000 cap", "paper physics: mean (stuck)"]
    if ce is not None:
        header.append("paper masses, correct physics, Euler: mean (stuck)")
    md.append(f"**Learning**, {len(gym['seeds'])} seeds × {TRIALS} trials (seeds below "
              f"{STUCK_BELOW:,} in brackets). The 2-SV edge {gym['edge']:g} m/s is the best of "
              f"the {len(EDGE_SCAN)}-edge scan ({EDGE_SCAN[0]:g} to {EDGE_SCAN[-1]:g}) on other "
              f"seeds ({GYM_SELECT_SEEDS}); the paper-physics column's 2-SV best edge is that "
              f"mode's own ({runs['2sv_best'].params.velocity_edge:g}), the last column's "
              + (f"{ce['edge']:g}" if ce else "—") + ".\n")
    md.append(_md_table(header, rows) + "\n")
    scan_best = max(gym["scan"])
    md.append(f"Gymnasium's pole falls fast under correct physics: with the angle alone (1 SV) "
              f"the network does not learn to balance it, as with the paper's masses under "
              f"correct physics. With the cart velocity cut at a small edge (2 SV) it learns: "
              f"the scan's best edge reached a mean of {scan_best:,.0f} on the selection seeds, "
              f"while at Table 1's 5 m/s edge the velocity input hardly ever changes in such "
              f"short trials and 2 SV does no better than 1 SV. Edge scan (selection seeds): "
              + ", ".join(f"{e:g}: {m:,.0f}" for e, m in zip(EDGE_SCAN, gym["scan"])) + ".\n")
    md.append("Data: " + ", ".join(f"`{rel(f)}`" for f in files) + ".\n")
    return "\n".join(md)


# ------------------------------------------------------------------------------------------------
# Command line
# ------------------------------------------------------------------------------------------------
OWN_FLAGS = {"nsv": "--nsv", "trials": "--trials", "velocity_edge": "--velocity-edge",
             "physics": "--physics"}


def learn_params(args) -> Params:
    values = {"nsv": str(args.nsv), "trials": str(args.trials)}
    if args.velocity_edge is not None:
        values["velocity_edge"] = args.velocity_edge
    if args.physics is not None:
        values["physics"] = args.physics
    for item in args.option:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"--option expects key=value, got {item!r}")
        if key in OWN_FLAGS:
            raise ValueError(f"set {key} with {OWN_FLAGS[key]}, not --option")
        values[key] = value.strip()
    return params_from_strings(values)


def cmd_calibrate(args) -> None:
    cal = calibrate()
    files = write_calibration(cal, Path(args.out))
    print_calibration(cal)
    print(f"wrote {len(files)} CSV files to {args.out}")


def cmd_learn(args) -> None:
    seeds = parse_seeds(args.seeds)
    p = learn_params(args)
    name = f"{p.nsv}sv"
    run = learn_run(name, f"{p.nsv} SV", seeds, p)
    files = write_learn_outputs(run, Path(args.out))
    print_seed_means(run)
    print("wrote " + ", ".join(str(f) for f in files))


def cmd_figures(args) -> None:
    seeds = parse_seeds(args.seeds)
    cal = calibrate()
    runs = main_runs(seeds, cal)
    figs = make_figures(cal, runs, Path(args.out))
    print(f"wrote {len(figs['paths'])} figures to {args.out}")


def cmd_all(args) -> None:
    start = time.perf_counter()
    seeds, amb_seeds = parse_seeds(args.seeds), parse_seeds(args.ambiguity_seeds)
    out = Path(args.out)
    data, fig_dir = out / "data", out / "figures"
    cal = calibrate()
    files = write_calibration(cal, data)
    print_calibration(cal)
    runs = main_runs(seeds, cal)
    for key in ("1sv", "2sv", "2sv_best"):
        files += write_learn_outputs(runs[key], data)
        print(f"{runs[key].label}: mean {runs[key].seed_means.mean():.1f}, "
              f"stuck {stuck(runs[key].seed_means)} of {len(seeds)}")
    physics = physics_runs(seeds, cal, runs)
    files.append(write_physics(physics, cal, data))
    amb = ambiguity(amb_seeds, cal)
    files += write_ambiguity(amb, data)
    figs = make_figures(cal, runs, fig_dir)
    gym = gymnasium_study(seeds, parse_seeds(GYM_SELECT_SEEDS))
    gym_files = write_gymnasium(gym, data)
    runtime = time.perf_counter() - start
    rel = lambda p: os.path.relpath(p, out)  # noqa: E731
    path = write_report(out / "REPRODUCTION.md", cal, runs, physics, amb, figs, seeds,
                        amb_seeds, runtime, files, args.seeds, args.ambiguity_seeds,
                        [gymnasium_markdown(gym, runs, physics, gym_files, rel)])
    print(f"wrote {path}, {len(figs['paths'])} figures, {len(files)} data files "
          f"in {time.perf_counter() - start:.0f} s")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.reproduce",
                                   description=__doc__.split("\n\n")[0],
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    c = sub.add_parser("calibrate", help="the paper's numbers (a)-(d) under every physics mode")
    c.add_argument("--out", default="out/calibrate", help="folder for the CSV files")
    c.set_defaults(func=cmd_calibrate)

    ln = sub.add_parser("learn", help="learning episodes with the batch engine, CSV + NPZ out")
    ln.add_argument("--nsv", type=int, choices=(1, 2), required=True,
                    help="state variables: 1 (angle) or 2 (angle and cart velocity)")
    ln.add_argument("--seeds", default=DEFAULT_SEEDS, help="seeds, e.g. 0-31, 0,3,5 or 0-3,7")
    ln.add_argument("--trials", type=int, default=TRIALS, help="trials per episode")
    ln.add_argument("--velocity-edge", type=str, default=None,
                    help=f"velocity edge in m/s (default: Table 1's {LITERAL_EDGE:g})")
    ln.add_argument("--physics", default=None, help="paper (default) or correct")
    ln.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                    help="any other Params field, e.g. tie_break=index (repeatable)")
    ln.add_argument("--out", default="out/learn", help="folder for learn_<n>sv.csv and weights")
    ln.set_defaults(func=cmd_learn)

    fg = sub.add_parser("figures", help="Figures 7-15 as PNG (runs what they need)")
    fg.add_argument("--out", default="out/figures", help="folder for the PNG files")
    fg.add_argument("--seeds", default=DEFAULT_SEEDS, help="seeds for the learning runs")
    fg.set_defaults(func=cmd_figures)

    al = sub.add_parser("all", help="everything, then writes OUT/REPRODUCTION.md")
    al.add_argument("--out", default="docs",
                    help="folder for REPRODUCTION.md, figures/ and data/")
    al.add_argument("--seeds", default=DEFAULT_SEEDS, help="seeds for the paper's runs")
    al.add_argument("--ambiguity-seeds", default=AMBIGUITY_SEEDS,
                    help="seeds for the one-option-at-a-time table")
    al.set_defaults(func=cmd_all)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except (ParamError, ValueError) as exc:
        print(f"python -m clnn_ros.reproduce {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. piped into `head`
        sys.stdout = open(os.devnull, "w")
        return 0
    except OSError as exc:
        print(f"python -m clnn_ros.reproduce {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
