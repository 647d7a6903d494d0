"""Faults of a running graph: each process killed outright in turn (kill -9), and a node that
stays alive but goes silent. The trial manager names the node, the graph comes down, run_all
exits 1 with one line, the bag holds every tick up to the fault, and nothing is left running."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from clnn_ros import bag
from clnn_ros.nodes.common import TRIAL_EVENT

from test_graph import processes_with, wait_for_line
from test_recording import assert_every_tick, child, raw_messages, start_run

from conftest import ros_environment

DOMAIN_ID = str(10 + os.getpid() % 20)
PROCESSES = ("environment", "encoder", "reward", "agent", "recorder", "trial_manager")


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)


def error_lines(stderr: str) -> list[str]:
    """run_all's own lines (the nodes' ROS log lines start with '[')."""
    return [line for line in stderr.splitlines() if line.startswith("run_all:")]


@pytest.mark.parametrize("node", PROCESSES)
def test_killed_process_is_named_and_the_graph_comes_down(ros_env, tmp_path, node):
    # A stall timeout far above the liveliness lease: only liveliness can name the node in time.
    process = start_run(ros_env, tmp_path, "--stall-timeout", "30")
    try:
        wait_for_line(process.stdout, "trial    2/")
    except AssertionError:
        os.killpg(process.pid, signal.SIGINT)
        pytest.fail(f"the run did not reach trial 2: {process.communicate(timeout=30)[1][-3000:]}")
    killed_at = time.time()
    os.kill(child(process, f"clnn_ros.nodes.{node}"), signal.SIGKILL)
    _, stderr = process.communicate(timeout=40)
    ended_after = time.time() - killed_at
    reason = ("the trial manager died (SIGKILL)" if node == "trial_manager" else
              f"node '{node}' died at tick ")
    assert process.returncode == 1, stderr
    lines = error_lines(stderr)
    assert len(lines) == 1 and lines[0].startswith("run_all: error: " + reason), stderr[-3000:]
    assert "Traceback" not in stderr
    if node != "trial_manager":  # its ROS log line carries the wall time it named the node
        named = next(line for line in stderr.splitlines() if "[trial_manager]" in line)
        assert float(named.split("[")[2].rstrip("] ")) - killed_at < 2.0, named
    assert ended_after < 10, ended_after  # named, the last messages delivered, all exited
    if node != "recorder":  # a killed recorder leaves its complete chunks (test_recording)
        messages = raw_messages(tmp_path / "run.mcap")
        assert assert_every_tick(messages) > 50
        if node != "trial_manager":
            events = [bag.deserialize(TRIAL_EVENT, m[4]) for m in messages if m[1] == TRIAL_EVENT]
            assert events[-1].event == 2 and reason in events[-1].end_reason
    assert not processes_with(str(tmp_path))


def test_silent_node_is_named_after_the_stall_timeout(ros_env, tmp_path):
    """Alive (its liveliness holds) but publishing nothing: the stall watchdog names it."""
    broken = Path(__file__).with_name("broken_env_node.py")
    process = start_run(ros_env, tmp_path, "--stall-timeout", "1",
                        "--env-node", f"python {broken} mute")
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 1
    assert error_lines(stderr) == ["run_all: error: stall: node 'environment' went silent at "
                                   "tick 50 (no progress for 1 s)"]
    assert assert_every_tick(raw_messages(tmp_path / "run.mcap")) == 49
    assert not processes_with(str(tmp_path))
