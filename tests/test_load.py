"""The graph on a loaded machine: more busy processes than cores (CPU hogs at the graph's own
priority) while 20 runs of 2,000+ ticks each run, five at a time in five namespaces of one ROS
domain (each run is load for the others too); every fifth as 5 processes with its recorder,
the others composed without one. No run may declare a healthy node dead or stalled, need a node terminated, or
differ from the core: slow is not dead."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from clnn_ros.core.episode import run_episode
from clnn_ros.core.params import Params

from test_graph import processes_with, read_steps

from conftest import free_domain_id, problem_lines, ros_environment

pytestmark = pytest.mark.ros  # every test here starts ROS / DDS
DOMAIN_ID = free_domain_id()
MAX_STEPS = 600
# seed: trials for 2,000-2,600 ticks at MAX_STEPS (core.run_episode)
RUNS = {0: 11, 1: 9, 2: 11, 3: 5, 4: 6, 5: 8, 6: 6, 7: 10, 8: 8, 9: 4, 10: 10, 11: 6, 12: 4,
        13: 4, 14: 9, 15: 11, 16: 8, 17: 4, 18: 5, 19: 5}
AT_ONCE = 5
HOGS = os.cpu_count() + 1


@pytest.fixture
def cpu_hogs():
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(HOGS)]
    try:
        yield len(hogs)
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()


def test_twenty_runs_beside_cpu_hogs_have_no_false_death_and_equal_the_core(
        tmp_path_factory, tmp_path, cpu_hogs):
    env = {**ros_environment(DOMAIN_ID, tmp_path_factory), "CLNN_TEST_RUN": str(tmp_path)}
    report, seeds = [], list(RUNS)
    while seeds:
        batch, seeds = seeds[:AT_ONCE], seeds[AT_ONCE:]
        started = time.monotonic()
        running = {seed: subprocess.Popen(
            [sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--namespace", f"load{seed}",
             "--seed", str(seed), "--trials", str(RUNS[seed]), "--max-steps", str(MAX_STEPS),
             "--out", str(tmp_path / str(seed)), *(["--composed", "--no-record"] if seed % 5 else [])], env=env, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True) for seed in batch}
        for seed, process in running.items():
            _, stderr = process.communicate(timeout=600)  # slow is allowed, never a failure
            summary = json.loads((tmp_path / str(seed) / "summary.json").read_text()) \
                if (tmp_path / str(seed) / "summary.json").exists() else {}
            report.append({"seed": seed, "exit": process.returncode, "ticks": summary.get("ticks"),
                           "ticks_per_s": round(summary.get("ticks_per_s") or 0),
                           "wall_s": round(time.monotonic() - started, 1),
                           "problems": problem_lines(stderr)})
            assert process.returncode == 0, (report[-1], stderr[-3000:])
            assert not report[-1]["problems"], report[-1]  # no error, no forced termination
            core = run_episode(seed, Params(trials=RUNS[seed], max_steps=MAX_STEPS))
            assert read_steps(tmp_path / str(seed)) == core.steps.tolist(), seed
            assert summary["ticks"] >= 2000, report[-1]
    print(json.dumps({"hogs": cpu_hogs, "runs": report}))
    assert len(report) == 20
    assert not processes_with(str(tmp_path))
