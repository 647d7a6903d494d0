"""The real ROS 2 graph (real processes, real DDS on loopback) against the core: equal results,
Ctrl-C (bad parameters: test_bad_input.py; faults: test_faults.py; refused messages:
test_fuzz.py)."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from clnn_ros.core.episode import run_episode
from clnn_ros.core.params import Params
from clnn_ros.session.rosenv import processes_with_env

from conftest import HANG_S, free_domain_id, not_lttng, ros_environment

pytestmark = pytest.mark.ros  # every test here starts ROS / DDS
DOMAIN_ID = free_domain_id()


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)


# A bound against a hang, never a speed bound: the 2-SV episode here (up to 15,000 ticks) ran
# past 120 s beside CPU hogs and another test file, alive and merely slow.
EPISODE_HANG_S = 600


def run_all(env, *args, timeout=EPISODE_HANG_S):
    return subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--quiet", *args], env=env,
                          capture_output=True, text=True, timeout=timeout)


def read_steps(out: Path) -> list[int]:
    with open(out / "trials.csv") as f:
        return [int(row["steps"]) for row in csv.DictReader(f)]


@pytest.mark.parametrize("composed", [False, True], ids=["processes", "composed"])
@pytest.mark.parametrize("nsv, options", [(1, []), (2, ["--velocity-edge", "0.3"])],
                         ids=["1sv", "2sv"])
def test_graph_equals_core(ros_env, tmp_path, composed, nsv, options):
    trials, max_steps, seed = 10, 800, 1  # 2 SV: 7 of the 10 trials reach the cap
    result = run_all(ros_env, "--seed", str(seed), "--nsv", str(nsv), "--trials", str(trials),
                     "--max-steps", str(max_steps), *options, "--out", str(tmp_path),
                     *(["--composed"] if composed else []))
    assert result.returncode == 0, result.stderr
    edge = float(options[1]) if options else 5.0
    core = run_episode(seed, Params(nsv=nsv, trials=trials, max_steps=max_steps,
                                    velocity_edge=edge))
    assert read_steps(tmp_path) == core.steps.tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), core.final_weights)
    assert "completed: 10 trials" in result.stdout


@pytest.mark.parametrize("composed", [False, True], ids=["processes", "composed"])
def test_a_run_paced_at_50_hz_equals_the_unpaced_one(ros_env, tmp_path, composed):
    """--rate 50: a tick at most every 20 ms of wall time (a robot's rate; issue 37), the same
    trials and weights as the core; the pace is a lower bound on the wall time, never a speed."""
    trials, max_steps, seed, rate = 3, 60, 1, 50
    result = run_all(ros_env, "--seed", str(seed), "--trials", str(trials), "--max-steps",
                     str(max_steps), "--rate", str(rate), "--no-record", "--out", str(tmp_path),
                     *(["--composed"] if composed else []))
    assert result.returncode == 0, result.stderr
    core = run_episode(seed, Params(trials=trials, max_steps=max_steps))
    assert read_steps(tmp_path) == core.steps.tolist()
    assert np.array_equal(np.load(tmp_path / "final_weights.npy"), core.final_weights)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["wall_s"] >= (summary["ticks"] - 1) / rate


@pytest.mark.parametrize("options", [
    {"state_vars": "pole_angle,cart_position"},
    {"state_vars": "cart_position,pole_angular_velocity,pole_angle", "first_action": "no_force",
     "physics": "integration_slip", "decay_counters": "carry", "punish_timing": "after_decay",
     "inference": "exact", "explore": 0.002, "rerandomize_every": 3,
     "rerandomize_fraction": 0.3, "rerandomize_range": 1.0}],
    ids=["angle and position", "3 SV, every new open choice"])
def test_graph_equals_core_for_other_encodings_and_choices(ros_env, tmp_path, options):
    # the encoder node encodes, the environment releases the pole, the agent learns as the core
    trials, max_steps, seed = 8, 800, 2
    given = [arg for name, value in options.items() if name != "state_vars"
             for arg in ("--option", f"{name}={value}")]
    result = run_all(ros_env, "--seed", str(seed), "--state-vars", options["state_vars"],
                     "--trials", str(trials), "--max-steps", str(max_steps), *given,
                     "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    core = run_episode(seed, Params(trials=trials, max_steps=max_steps, **options))
    assert read_steps(tmp_path) == core.steps.tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), core.final_weights)
    assert f"state {options['state_vars']}" in result.stdout


def test_ctrl_c_stops_everything(ros_env, tmp_path, in_private_shm):
    """Ctrl-C in a terminal: run_all and every node exit, none is left, and nothing is left in
    /dev/shm (where allowed the run has a /dev/shm of its own, listed after run_all exited)."""
    marker = {**ros_env, "CLNN_TEST_RUN": str(tmp_path), "LISTING": str(tmp_path / "shm.txt")}
    list_after = ["sh", "-c", 'trap true INT; "$@"; code=$?; ls /dev/shm > "$LISTING"; '
                              'exit $code', "_"]
    process = subprocess.Popen(
        [*in_private_shm, *list_after, sys.executable, "-m", "clnn_ros.run_all", "--seed", "1",
         "--trials", "400", "--out", str(tmp_path)],
        env=marker, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True)
    wait_for_line(process.stdout, "trial    2/", errors=process.stderr)
    os.killpg(process.pid, signal.SIGINT)  # what a terminal does on Ctrl-C
    stdout, stderr = process.communicate(timeout=HANG_S)
    assert process.returncode == 130, stderr
    assert "run_all: interrupted" in stderr and "Traceback" not in stderr
    if in_private_shm:
        left = not_lttng((tmp_path / "shm.txt").read_text().split())
        assert not left, left
    assert not processes_with(marker["CLNN_TEST_RUN"])


def wait_for_line(stream, text: str, timeout: float = 180.0, errors=None) -> str:
    """The first line with `text`; the timeout bounds a hang, it times nothing. Without one,
    the stream's last lines read say what came instead, and `errors` (the process's standard
    error, a pipe) what it said once the stream ended: why a run ended before the line."""
    found, seen = [], []

    def read():
        for line in stream:
            if text in line:
                found.append(line)
                return
            seen.append(line)
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout)
    ended = "the stream ended" if not reader.is_alive() else f"none within {timeout} s"
    said = []
    if not found and errors is not None and not reader.is_alive():
        rest = threading.Thread(target=lambda: said.append(errors.read()), daemon=True)
        rest.start()
        rest.join(30)
    assert found, (f"no line with {text!r}: {ended}; its last lines:\n{''.join(seen[-20:])}"
                   + (f"\nits standard error:\n{said[0][-3000:]}" if said else ""))
    return found[0]


def processes_with(marker: str) -> list[int]:
    """Processes whose environment holds CLNN_TEST_RUN=marker (run_all and the nodes it starts)."""
    return processes_with_env("CLNN_TEST_RUN", marker)
