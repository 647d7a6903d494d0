"""The reproduction's outputs on small inputs (clnn_ros.reproduce): the claims table, the report's
sections and tables, the CSV writers and the figures; hand-made calibration numbers and tiny
learning runs instead of the paper's."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest

from clnn_ros.core.episode import angle_grid
from clnn_ros.core.params import Params
from clnn_ros.core.physics import CONTINUE, FAIL_ANGLE, FAIL_POSITION
from clnn_ros.reproduce.calibration import Calibration, ModeCalibration, write_calibration
from clnn_ros.reproduce.claims import NEARLY_ALL_CAPPED, claims_table
from clnn_ros.reproduce.common import EDGE_SCAN, LITERAL_EDGE, MAX_STEPS, MODES, PAPER
from clnn_ros.reproduce.figures import Figures, figures_markdown, make_figures
from clnn_ros.reproduce.gymnasium_physics import (Agreement, GymLearning, GymnasiumStudy,
                                                  gymnasium_markdown, write_gymnasium)
from clnn_ros.reproduce.learning import PaperRuns, learn_run
from clnn_ros.reproduce.local_optima import EXPLORE, ExploreRun, local_optima_markdown
from clnn_ros.reproduce.open_choices import (DEFAULTS, VELOCITY_EDGE, OptionRun,
                                             open_choices_markdown, write_open_choices)
from clnn_ros.reproduce.physics_modes import ModeLearning, physics_markdown, write_physics
from clnn_ros.reproduce.sensitivity import (FACTORS, SWEPT, Sensitivity, sensitivity_markdown,
                                          sensitivity_verdict)
from clnn_ros.reproduce.report import (claims_markdown, data_files_markdown, header_markdown,
                                       write_report)

BEST_EDGE = EDGE_SCAN[10]
GRID = angle_grid(Params())
SEEDS = [0, 1, 2]


def _mode(plus=(PAPER["constant_force_steps"], FAIL_POSITION), literal_capped=32) -> ModeCalibration:
    """Numbers that give each verdict its 'matches' side, unless changed."""
    n = len(GRID)
    fig7_status = np.full(n, FAIL_POSITION)
    fig7_status[np.argsort(np.abs(GRID))[:4]] = CONTINUE  # the four angles nearest 0
    fig7_steps = np.where(fig7_status == CONTINUE, MAX_STEPS, 5000)
    fig12_steps = np.full((len(EDGE_SCAN), n), 300)
    fig12_status = np.full((len(EDGE_SCAN), n), FAIL_ANGLE)
    for edge, capped in ((LITERAL_EDGE, literal_capped), (BEST_EDGE, 32)):
        row = EDGE_SCAN.index(edge)
        fig12_status[row, :capped], fig12_steps[row, :capped] = CONTINUE, MAX_STEPS
    return ModeCalibration(no_force_steps=np.full(n, 270), no_force_status=np.full(n, FAIL_ANGLE),
                           plus=plus, minus=(PAPER["constant_force_steps"], FAIL_POSITION),
                           fig7_steps=fig7_steps, fig7_status=fig7_status, fig12_steps=fig12_steps,
                           fig12_status=fig12_status, best_edge=BEST_EDGE)


def _calibration(**paper_mode) -> Calibration:
    modes = {mode: _mode() for mode in MODES}
    modes[MODES[0]] = _mode(**paper_mode)
    return Calibration(grid=GRID, modes=modes, fig7_sensitivity={"grid": 6000.0, "grid + 1": 7000.0},
                       fig12_literal_max_speed=0.5, fig12_reversed_intervals=[3, 4])


@pytest.fixture(scope="module")
def runs() -> PaperRuns:
    return PaperRuns(learn_run("1sv", "1 SV", SEEDS, Params(nsv=1, trials=6)),
                     learn_run("2sv", "2 SV, literal edge 5", SEEDS, Params(nsv=2, trials=6)),
                     learn_run(f"2sv_edge{BEST_EDGE:g}", f"2 SV, scan's best edge {BEST_EDGE:g}",
                               SEEDS, Params(nsv=2, trials=6, velocity_edge=BEST_EDGE)))


def _verdicts(cal: Calibration, runs: PaperRuns) -> dict[str, str]:
    return {claim: why for claim, _, _, why in claims_table(cal, runs)}


def test_claims_table(runs):
    rows = claims_table(_calibration(), runs)
    assert len(rows) == 11 and all(len(r) == 4 and all(isinstance(c, str) for c in r) for r in rows)
    why = _verdicts(_calibration(), runs)
    assert why["(b) constant ±F: cart leaves the track after"] == "matches exactly"
    assert why["Figure 8: angles near 0 reach 10,000, the others 3,000-9,000"] == "same pattern"
    assert why["(d)/Figure 13: Figure 12 weights, literal edge 5"] == "matches"
    assert why[f"(d)/Figure 13: Figure 12 weights, scan's best edge {BEST_EDGE:g}"].startswith(
        f"matches for edges {BEST_EDGE:g}-{LITERAL_EDGE:g} m/s")  # both rows capped: one plateau


def test_claims_table_differs(runs):
    why = _verdicts(_calibration(plus=(33, FAIL_POSITION), literal_capped=NEARLY_ALL_CAPPED - 1),
                    runs)
    assert why["(b) constant ±F: cart leaves the track after"] == "differs"
    assert why["(d)/Figure 13: Figure 12 weights, literal edge 5"].startswith(
        "|dx/dt| stays below 0.50 m/s")
    assert "angle interval(s) 3, 4" in why["(d)/Figure 13: Figure 12 weights, literal edge 5"]


def _gymnasium_study() -> GymnasiumStudy:
    steps = np.full((len(SEEDS), 4), 50)
    return GymnasiumStudy(
        edge=BEST_EDGE, scan=[100.0] * len(EDGE_SCAN),
        learning=tuple(GymLearning(label, steps) for label in ("1 SV", "2 SV", "2 SV best")),
        agreement=[Agreement("1 SV", 0, 4, 4, None, 50.0, 50.0, 60, 60),
                   Agreement("2 SV best", 0, 4, 2, 2, 70.0, 60.0, 80, 900)],
        seeds=np.array(SEEDS), max_steps=MAX_STEPS)


def _physics() -> dict:
    means = np.array([500.0, 2000.0, 3000.0])
    return {mode: ModeLearning(BEST_EDGE, (means, means, means)) for mode in MODES}


def _options() -> list[OptionRun]:
    seeds, means = np.array(SEEDS), np.array([500.0, 2000.0, 3000.0])
    return [OptionRun(DEFAULTS, "", 1, LITERAL_EDGE, seeds, means),
            OptionRun(DEFAULTS, "", 2, LITERAL_EDGE, seeds, means),
            OptionRun(DEFAULTS, "", 2, BEST_EDGE, seeds, means),
            OptionRun("tie_break", "index", 1, LITERAL_EDGE, seeds, means),
            OptionRun(VELOCITY_EDGE, "0.5", 2, 0.5, seeds, means, fig12_mean=4000.0)]


def _sensitivity() -> list[Sensitivity]:
    """1 SV: every parameter within 10 % at x 1/2 and x 2 but sigma (halved: -50 %)."""
    base = np.array([1000.0, 2000.0, 3000.0])
    rows = {(name, factor): base * (0.5 if (name, factor) == ("sigma", 0.5) else 1.05)
            for name in SWEPT for factor in FACTORS}
    return [Sensitivity(Params(), "1 SV", base, rows)]


def _explore_runs() -> list[ExploreRun]:
    steps = np.array([[500.0] * 4, [5000.0] * 4, [8000.0] * 4])
    return [ExploreRun("1 SV", e, steps + (600.0 if e else 0.0)) for e in EXPLORE]


def _tables(text: str) -> list[list[str]]:
    """Each Markdown table in `text` as its lines."""
    return [block.splitlines() for block in re.findall(r"(?:^\|.*\|$\n?)+", text, re.M)]


def test_report_sections_and_tables(tmp_path, runs):
    cal, gym = _calibration(), _gymnasium_study()
    data, report = tmp_path / "data", tmp_path / "REPRODUCTION.md"
    files = write_calibration(cal, data)
    gym_files = write_gymnasium(gym, data)
    figs = Figures(paths={"fig07": tmp_path / "figures" / "fig07.png"}, traces={"fig15": None})
    rel = lambda p: str(Path(p).relative_to(tmp_path))  # noqa: E731
    sections = [header_markdown(123.4, SEEDS, "0-2", SEEDS, "0-2", 6000.0),
                claims_markdown(cal, runs), figures_markdown(figs, runs, rel),
                physics_markdown(cal, _physics(), len(SEEDS)),
                open_choices_markdown(_options(), BEST_EDGE, len(SEEDS)),
                sensitivity_markdown(_sensitivity(), len(SEEDS)),
                local_optima_markdown(_explore_runs(), "figures/local_optima.png"),
                data_files_markdown(files, tmp_path),
                gymnasium_markdown(gym, runs, _physics(), gym_files, rel)]
    assert write_report(report, sections) == report
    text = report.read_text()
    assert text == "\n".join(sections)
    assert "Runtime 123 s on" in text and "3 seeds (0-2) for the paper's runs" in text
    titles = re.findall(r"^## (.*)$", text, re.M)
    assert titles == ["Paper vs measured", "Figures", "Paper physics vs correct physics",
                      "Open choices, one at a time", "Sensitivity to the Table 2 parameters",
                      "Local optima: a way out", "Data files", "Gymnasium's physics (CartPole-v1)"]
    assert "![fig07](figures/fig07.png)" in text
    assert re.search(r"\*\*Figure 15: steps 5000-6000 of a successful 2-SV trial[^*]*\*\* "
                     r"Not drawn", text)
    assert "All in `data/`: `calib_no_force.csv`" in text
    assert "| 1 SV | 0 | 4/4 | — |" in text and "| 2 SV best | 0 | 2/4 | 2 |" in text
    tables = _tables(text)
    # claims, sensitivity of Fig. 7, 2 physics, 2 options, Table 2 sensitivity (one encoding),
    # local optima, 2 gymnasium
    assert len(tables) == 10
    for table in tables:
        cells = {len(re.split(r"(?<!\\)\|", line)) for line in table}
        assert len(cells) == 1, table  # every row has the header's columns


def test_csv_writers(tmp_path):
    cal, gym = _calibration(), _gymnasium_study()
    files = write_calibration(cal, tmp_path)
    assert [f.name for f in files] == ["calib_no_force.csv", "calib_constant_force.csv",
                                       "calib_fig7.csv", "calib_fig12_edge_scan.csv",
                                       "calib_summary.csv", "calib_fig7_sensitivity.csv"]
    rows = {f.name: list(csv.reader(open(f, newline=""))) for f in files}
    assert len(rows["calib_fig12_edge_scan.csv"]) == 1 + len(MODES) * len(EDGE_SCAN) * len(GRID)
    summary = rows["calib_summary.csv"][1]
    assert summary[:2] == list(MODES[0]) and summary[-2:] == [f"{BEST_EDGE}", "10000.0"]
    agreement = list(csv.DictReader(open(write_gymnasium(gym, tmp_path)[2], newline="")))
    assert [a["first_differing_trial"] for a in agreement] == ["", "2"]
    physics = list(csv.DictReader(open(write_physics(_physics(), tmp_path), newline="")))
    assert len(physics) == len(MODES) and physics[0]["stuck_1sv"] == "1"
    summary, per_seed = write_open_choices(_options(), tmp_path)
    assert len(list(csv.reader(open(summary)))) == 1 + 5
    assert len(list(csv.reader(open(per_seed)))) == 1 + 5 * len(SEEDS)


def test_make_figures_writes_every_png(tmp_path, runs):
    figs = make_figures(_calibration(), runs, tmp_path)
    drawn = {"fig07", "fig12", "fig08", "fig13", "edge_scan", "fig09", "learning_curves_1sv",
             "learning_curves_2sv", f"learning_curves_2sv_edge{BEST_EDGE:g}",
             "fig14_literal_edge", "fig14_best_edge"}
    assert drawn <= set(figs.paths)
    assert set(figs.traces) == {"fig10", "fig11", "fig15"}
    for name, trace in figs.traces.items():
        assert (name in figs.paths) == (trace is not None)
    for name, path in figs.paths.items():
        assert path == tmp_path / f"{name}.png"
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_sensitivity_verdict_names_what_moves():
    verdict = sensitivity_verdict(_sensitivity())
    assert "1 SV: it holds for omega, rho_plus, rho_minus, punish, segments, w_max; not for " \
           "sigma (50%)." in verdict


def test_local_optima_table_and_verdict():
    md = local_optima_markdown(_explore_runs(), "figures/local_optima.png")
    assert "| 1 SV | 0 | 4,500 | 1 | 4,500 | 1 |" in md
    assert "explore = 0.001 leaves 0 seeds stuck (deterministic: 1)" in md
    assert "![local optima](figures/local_optima.png)" in md
