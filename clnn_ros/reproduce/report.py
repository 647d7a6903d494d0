"""The report docs/REPRODUCTION.md: a header, the claims table and the sections each experiment
writes, joined in order."""

from __future__ import annotations

import os
from pathlib import Path

from .calibration import Calibration
from .claims import FIG14_BETTER, FIG14_WORSE, claims_table
from .common import STUCK_BELOW, TRIALS, md_table
from .learning import PaperRuns

COMMAND = "python -m clnn_ros.reproduce all"


def header_markdown(runtime_s: float, seeds: list[int], seed_spec: str, option_seeds: list[int],
                    option_spec: str, opt1: float) -> str:
    """The title, how the report was made (the runtime line) and the conventions; `opt1` is the
    optimal 1-SV mean the Figure 14 bands are relative to."""
    return "\n".join([
        "# Reproduction report: Smith (2024), online RL with clustering neural networks\n",
        f"> **Generated** by `{COMMAND}` (clnn_ros/reproduce/). Do not edit by hand: every "
        f"number below is measured by that command. Runtime {runtime_s:.0f} s on "
        f"{os.cpu_count()} CPU cores. {len(seeds)} seeds ({seed_spec}) for the "
        f"paper's runs, {len(option_seeds)} seeds ({option_spec}) for the option table; {TRIALS} "
        f"trials per episode.\n",
        "Beyond the paper (learning under Gymnasium's physics, out of the local optima, the "
        "paper's re-randomization proposal measured): [LEARNING.md](LEARNING.md), made by "
        "`python -m clnn_ros.reproduce goals`.\n",
        "Conventions: the project's `paper` defaults (`clnn_ros.core.params.Params`, see "
        "the module docstrings and the conventions note): paper physics (θ̈ too small by "
        "180/π), semi-implicit Euler, ties broken by exact sums, only the action path tagged, "
        "e flag latched, success counter reset per trial, seed protocol "
        "`numpy.random.default_rng(seed)`. Every run except the three traces uses the numba "
        "batch engine (`clnn_ros.batch`), which is tested equal to the pure core trial by "
        "trial. Thresholds used below: a seed is *stuck* when its mean is below "
        f"{STUCK_BELOW:,} steps; Figure 14 bands are relative to the optimal 1-SV mean "
        f"({opt1:,.0f}): better above {FIG14_BETTER:g}×, worse below {FIG14_WORSE:g}×.\n"])


def claims_markdown(cal: Calibration, runs: PaperRuns) -> str:
    return "\n".join([
        "## Paper vs measured\n",
        md_table(["claim", "paper", "measured", "why it differs / note"],
                 [list(r) for r in claims_table(cal, runs)]) + "\n",
        "Sensitivity of (c) to the start angles (Figure 7 weights, paper physics):\n",
        md_table(["angle grid", "mean steps"],
                 [[k, f"{v:,.1f}"] for k, v in cal.fig7_sensitivity.items()]) + "\n"])


def data_files_markdown(data_files: list[Path], report_dir: Path) -> str:
    return "\n".join([
        "## Data files\n",
        "All in `" + os.path.relpath(data_files[0].parent, report_dir) + "/`: "
        + ", ".join(f"`{p.name}`" for p in data_files) + ". Per-trial CSVs have columns "
        "seed, trial, initial_angle_deg, steps, end_reason (max_steps, pole_angle, "
        "cart_position); final-weight CSVs seed, neuron (0 = −F, 1 = +F), segment, input "
        "(0-based: angle intervals, then velocity intervals), weight.\n"])


def write_report(path: Path, sections: list[str]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(sections))
    return path
