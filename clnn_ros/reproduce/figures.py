"""Figures 7-15 (plus the edge scan and the learning curves) as PNGs, the traces of Figures 10, 11
and 15 (the core replays one trial of a learned episode), and their captions in the report."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .. import figures as plots
from ..batch import run_batch
from ..core.optimal import optimal_weights
from ..core.params import Params
from ..core.physics import CONTINUE, FAIL_POSITION
from ..core.agent import RLNAgent
from .calibration import Calibration
from .common import (EDGE_SCAN, END_REASONS, LITERAL_EDGE, MAX_STEPS, PAPER, mode_label, progress,
                     trace_trial)
from .learning import PaperRuns, Run

# ------------------------------------------------------------------------------------------------
# Settings
# ------------------------------------------------------------------------------------------------
SUCCESS_SECTION = (5000, 6000)  # steps shown for "a section of a successful trial" (Figs 11, 15)
# Table 1's angle intervals [-1, 0) and [0, 1) deg: an oscillation within +-1 deg visits only them.
CENTRAL_INTERVALS = (3, 4)
CENTRAL_SPAN_DEG = 1.0


@dataclass
class Trace:
    """One trial of a learned episode, replayed through the core with learning on."""
    seed: int
    seed_mean: float  # that seed's mean steps while learning
    trial: int  # the trial of the episode
    angle: float  # initial angle, deg
    weights: np.ndarray  # at the trial's start
    params: Params
    steps: int  # the trial's steps and end status in the episode (batch engine)
    status: int
    states: np.ndarray  # (steps, 4) from step `first` on
    first: int  # the step of states[0]


@dataclass
class Figures:
    paths: dict[str, Path]  # figure name -> PNG
    traces: dict[str, Trace | None]  # fig10, fig11, fig15; None where no such trial exists


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


def uses_velocity(weights: np.ndarray, p: Params) -> bool:
    """Whether 2-SV weights choose by the velocity input in a central angle interval (where a
    balanced pole spends its time): the rule that picks Figure 15's seed."""
    return not set(CENTRAL_INTERVALS) <= set(velocity_ignored(weights, p))


def pick_trace(run: Run, want: str, seed_rule: Callable[[np.ndarray, Params], bool] | None = None
               ) -> Trace | None:
    """A typical trial of a learned episode, as the paper's Figures 10, 11 and 15 show: seeds
    are tried from the one whose mean is closest to the median seed mean outwards (those whose
    final weights pass `seed_rule`); among the trials of the episode's second half that ended
    as wanted ("cart" = failed by the cart, "cap" = reached the cap) the one with the median
    step count is replayed through the core, learning, from the weights the batch engine had
    at its start."""
    means = run.seed_means
    order = np.argsort(np.abs(means - np.median(means)), kind="stable")
    r, p = run.result, run.params
    for k in order:
        if seed_rule is not None and not seed_rule(r.final_weights[k], p):
            continue
        wanted = FAIL_POSITION if want == "cart" else CONTINUE
        half = r.steps.shape[1] // 2
        candidates = half + np.flatnonzero(r.end_status[k, half:] == wanted)
        if not len(candidates):
            continue
        trial = int(candidates[np.argsort(r.steps[k, candidates], kind="stable")
                               [len(candidates) // 2]])
        seed = int(r.seeds[k])
        weights = run_batch([seed], p.replace(trials=trial)).final_weights[0]
        shown = p.replace(max_steps=min(p.max_steps, SUCCESS_SECTION[1])) if want == "cap" else p
        angle = float(r.initial_angles[k, trial])
        states, steps, status = trace_trial(weights, angle, shown, learn=True, seed=seed)
        if want == "cart" and (steps, status) != (r.steps[k, trial], r.end_status[k, trial]):
            raise RuntimeError(f"seed {seed} trial {trial}: the core's replay ({steps} steps) "
                               f"is not the episode's ({r.steps[k, trial]})")
        first = max(0, min(SUCCESS_SECTION[0], len(states) - 1)) if want == "cap" else 0
        return Trace(seed=seed, seed_mean=float(means[k]), trial=trial, angle=angle,
                     weights=weights, params=p, steps=int(r.steps[k, trial]),
                     status=int(r.end_status[k, trial]), states=states[first:], first=first)
    return None


def make_figures(cal: Calibration, runs: PaperRuns, out: Path) -> Figures:
    """Figures 7-15 (plus the edge scan and learning curves) as PNGs in `out`, and the traces."""
    out.mkdir(parents=True, exist_ok=True)
    paper_mode, grid, best_edge = cal.paper, cal.grid, cal.best_edge
    opt1 = float(paper_mode.fig7_steps.mean())
    opt2 = {e: float(paper_mode.fig12_steps_at(e).mean()) for e in (LITERAL_EDGE, best_edge)}
    one = runs.one_sv
    jobs = [
        ("fig07", lambda p: plots.plot_weights(optimal_weights(1), p,
                                               "Figure 7: optimal weights, 1 SV")),
        ("fig12", lambda p: plots.plot_weights(optimal_weights(2), p,
                                               "Figure 12: optimal weights, 2 SV")),
        ("fig08", lambda p: plots.plot_steps_per_angle(
            [("paper physics, semi-implicit Euler", grid, paper_mode.fig7_steps,
              paper_mode.fig7_status, {"paper's mean": PAPER["fig7_mean"]})], p,
            "Figure 8: steps per initial angle, Figure 7 weights (1 SV)", MAX_STEPS)),
        ("fig13", lambda p: plots.plot_steps_per_angle(
            [(f"velocity edge {e:g} m/s" + (" (Table 1, literal)" if e == LITERAL_EDGE
                                             else " (best of the scan)"),
              grid, paper_mode.fig12_steps_at(e), paper_mode.fig12_status_at(e), {})
             for e in (LITERAL_EDGE, best_edge)], p,
            "Figure 13: steps per initial angle, Figure 12 weights (2 SV)", MAX_STEPS)),
        ("edge_scan", lambda p: plots.plot_edge_scan(
            np.array(EDGE_SCAN), {mode_label(*k): m.fig12_steps.mean(axis=1)
                                  for k, m in cal.modes.items()}, p,
            "Figure 12 weights vs the velocity edge", {"literal (Table 1)": LITERAL_EDGE,
                                                       "best (paper/semi_implicit)": best_edge},
            MAX_STEPS)),
        ("fig09", lambda p: plots.plot_seed_means(
            one.result.seeds, one.seed_means, p,
            f"Figure 9: 1 SV, mean steps over {one.result.steps.shape[1]} trials per seed",
            {"optimal 1 SV (Figure 7)": opt1, "mean of the seeds": float(one.seed_means.mean())},
            max_steps=MAX_STEPS)),
    ]
    for run in runs.all():
        lines = {"optimal 1 SV": opt1}
        if run.params.nsv == 2:
            lines[f"optimal 2 SV, edge {run.params.velocity_edge:g}"] = opt2[run.params.velocity_edge]
        jobs.append((f"learning_curves_{run.name}", lambda p, run=run, lines=lines:
                     plots.plot_learning_curves(run.result.steps, p,
                                                f"Learning curves, {run.label}", lines, MAX_STEPS)))
    for run, tag in ((runs.two_sv_literal, "literal_edge"), (runs.two_sv_best, "best_edge")):
        e = run.params.velocity_edge
        jobs.append((f"fig14_{tag}", lambda p, run=run, e=e: plots.plot_seed_means(
            run.result.seeds, run.seed_means, p, f"Figure 14: {run.label}, seeds sorted",
            {"optimal 1 SV": opt1, f"optimal 2 SV (edge {e:g})": opt2[e],
             "1 SV learned, mean of the seeds": float(one.seed_means.mean())},
            sort=True, max_steps=MAX_STEPS)))
    paths = {name: plot(out / f"{name}.png") for name, plot in progress(jobs, "figures")}

    limits = (Params().angle_limit_deg, Params().track_limit_m)
    trace_jobs = (("fig10", runs.one_sv, "cart", None, "Figure 10: a typical failing trial"),
                  ("fig11", runs.one_sv, "cap", None, "Figure 11: a section of a successful trial"),
                  ("fig15", runs.two_sv_best, "cap", uses_velocity,
                   "Figure 15: a section of a successful trial"))
    traces = {}
    for name, run, want, rule, title in progress(trace_jobs, "traces"):
        t = traces[name] = pick_trace(run, want, rule)
        if t is None:
            continue
        detail = (f"{run.label}; seed {t.seed} (episode mean {t.seed_mean:.0f}), trial {t.trial} "
                  f"of its episode, learning; start {t.angle:+.3f} deg; {t.steps} steps, "
                  f"{END_REASONS[t.status].replace('_', ' ')}")
        paths[name] = plots.plot_trace(t.states, t.first, out / f"{name}.png",
                                       f"{title}\n{detail}", *limits)
    return Figures(paths, traces)


def fig15_note(t: Trace) -> str:
    """Why the Figure 15 trial moves as it does: where its weights ignore the velocity input."""
    ignored = velocity_ignored(t.weights, t.params)
    like_1sv = (set(CENTRAL_INTERVALS) <= set(ignored)
                and np.abs(t.states[:, 2]).max() < CENTRAL_SPAN_DEG)
    return (" In this seed's learned weights the action does not depend on the velocity input in "
            f"angle interval(s) {', '.join(map(str, ignored)) or 'none'}"
            + (", the only ones this oscillation visits, so it moves like a 1-SV trial."
               if like_1sv else "."))


def figures_markdown(figs: Figures, runs: PaperRuns, rel: Callable[[Path], str]) -> str:
    section = f"steps {SUCCESS_SECTION[0]}-{SUCCESS_SECTION[1]}"
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
        f"learning_curves_{runs.two_sv_best.name}": "Learning curves, 2 SV at the scan's best edge.",
        "fig10": "Figure 10: a typical failing 1-SV trial of a learned episode (the median seed's "
                 "trials of the second half that the cart ended: the one of median length, "
                 "replayed through the core, learning; each axis scaled to the motion).",
        "fig11": f"Figure 11: {section} of a successful 1-SV trial of a learned episode (chosen "
                 f"as for Figure 10 among the trials that reached the cap).",
        "fig14_literal_edge": "Figure 14: 2-SV per-seed means, sorted, literal edge.",
        "fig14_best_edge": "Figure 14: 2-SV per-seed means, sorted, the scan's best edge.",
        "fig15": f"Figure 15: {section} of a successful 2-SV trial of a learned episode, from the "
                 f"seed nearest the median whose learned weights choose by the velocity input in a "
                 f"central angle interval ([-1,0) or [0,1) deg, where a balanced pole stays).",
    }
    if figs.traces.get("fig15") is not None:
        captions["fig15"] += fig15_note(figs.traces["fig15"])
    md = ["## Figures\n"]
    for name, caption in captions.items():
        if name in figs.paths:
            md.append(f"**{caption}**\n\n![{name}]({rel(figs.paths[name])})\n")
        else:
            md.append(f"**{caption}** Not drawn: no such trial in these runs.\n")
    return "\n".join(md)
