"""Faults of a running graph and of its start: each process killed outright in turn (kill -9),
paused (SIGSTOP for 3 s, then SIGCONT), a node that stays alive but goes silent or sends a wrong
tick, a node that fails at start, run_all itself killed. run_all names the process that failed
(by its exit, at once) or the node whose output was missing (the stall watchdog), exits 1 with
one line, the bag is finalized, and nothing is left running."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from clnn_ros.graph import names
from clnn_ros.core.episode import run_episode
from clnn_ros.core.params import Params

from test_graph import processes_with, wait_for_line
from test_recording import assert_every_tick, child, raw_messages, start_run

from conftest import HANG_S, free_domain_id, problem_lines, ros_environment

pytestmark = pytest.mark.ros  # every test here starts ROS / DDS
DOMAIN_ID = free_domain_id()
PROCESSES = ("environment", "encoder", "reward", "agent", "recorder", "trial_manager")
BROKEN = Path(__file__).with_name("broken_env_node.py")


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)


class ReadLines:
    """A process's stderr read line by line on a thread (so that the pipe never fills)."""

    def __init__(self, stream):
        self.lines = []
        self.reader = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self.reader.start()

    def _read(self, stream) -> None:
        for line in stream:
            self.lines.append(line.rstrip("\n"))

    def text(self) -> str:
        self.reader.join(timeout=30)
        return "\n".join(self.lines)


@pytest.mark.parametrize("node", PROCESSES)
def test_killed_process_is_named_at_once_and_the_graph_comes_down(ros_env, tmp_path, node):
    # With a 30 s stall timeout the watchdog cannot have spoken: a line that names the signal
    # comes from the process's exit (no time is asserted: a loaded machine takes its time).
    process = start_run(ros_env, tmp_path, "--stall-timeout", "30")
    stderr = ReadLines(process.stderr)
    try:
        wait_for_line(process.stdout, "trial    2/", errors=process.stderr)
    except AssertionError:
        os.killpg(process.pid, signal.SIGINT)
        pytest.fail(f"the run did not reach trial 2: {stderr.text()[-3000:]}")
    os.kill(child(process, f"clnn_ros.nodes.{node}"), signal.SIGKILL)
    process.wait(timeout=120)
    text = stderr.text()
    assert process.returncode == 1, text[-3000:]
    # the recorder's bag is unfinished: its one line also says how to save what it holds
    repair = f"; the bag {tmp_path / 'bag'} is not finished, its complete chunks: python -m " \
             f"clnn_ros.bag repair {tmp_path / 'bag'} [--out DIR]" if node == "recorder" else ""
    assert problem_lines(text) == [f"run_all: error: node '{node}' died (SIGKILL){repair}"], \
        text[-3000:]
    assert "Traceback" not in text
    if node != "recorder":  # a killed recorder leaves its complete chunks (test_recording)
        # Finalized (read without --salvage): every tick up to the fault, but for what the
        # killed process had sent and nobody had received yet.
        messages = raw_messages(tmp_path / "bag")
        assert assert_every_tick(messages, tail_allowance=2) > 50
    assert not processes_with(str(tmp_path))


@pytest.mark.parametrize("fault", ["none", "agent", "trial_manager", "contract_v3"])
def test_the_last_line_is_the_verdict_with_the_bag_before_it(ros_env, tmp_path, fault):
    """A node killed (-9), the trial manager killed, an environment node refused, or none:
    stdout and stderr together, as a terminal or a script reading the last line sees them, end
    with the verdict, the bag's line before it (issue 47: the error stood above `run_all:
    bag`)."""
    output = tmp_path / "output.txt"
    extra = ["--env-node", f"python {BROKEN} contract_v3"] if fault == "contract_v3" else []
    with open(output, "w") as both:
        process = subprocess.Popen(
            [sys.executable, "-m", "clnn_ros.run_all", "--seed", "1", "--trials",
             "2" if fault == "none" else "400", "--out", str(tmp_path), "--stall-timeout", "30",
             *extra],
            env={**ros_env, "CLNN_TEST_RUN": str(tmp_path)}, stdout=both, stderr=both,
            start_new_session=True)
    try:
        if fault not in ("none", "contract_v3"):
            deadline = time.monotonic() + HANG_S
            while "trial    2/" not in output.read_text() and time.monotonic() < deadline:
                time.sleep(0.1)
            os.kill(child(process, f"clnn_ros.nodes.{fault}"), signal.SIGKILL)
        process.wait(timeout=HANG_S)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    lines = output.read_text().splitlines()
    assert process.returncode == (0 if fault == "none" else 1), lines[-20:]
    verdict = {"none": "run_all: completed: 2 trials",
               "agent": "run_all: error: node 'agent' died (SIGKILL)",
               "trial_manager": "run_all: error: node 'trial_manager' died (SIGKILL)",
               "contract_v3": "run_all: error: the environment node speaks contract version 3 "
                              "or older"}[fault]
    assert lines[-1].startswith(verdict), lines[-20:]
    # the bag's line before it, or before the summary of how far the run went, then the verdict
    bag_line = next(line for line in reversed(lines) if line.startswith("run_all: bag ") or
                    line == "run_all: nothing recorded, no bag")
    after = lines[lines.index(bag_line) + 1:-1]
    assert bag_line in (f"run_all: bag {tmp_path / 'bag'}", "run_all: nothing recorded, no bag")
    assert after == [] or (len(after) == 1 and " trials, mean steps " in after[0]), lines[-20:]
    assert not processes_with(str(tmp_path))


def test_a_node_stopped_by_someone_else_is_named(ros_env, tmp_path):
    """SIGTERM to one node (it ends with status 0, before the episode's end): the trial manager
    never ends, and with a stall timeout longer than the grace run_all names the node once the
    trial manager has had SHUTDOWN_GRACE_S of time to end (supervise.Grace)."""
    process = start_run(ros_env, tmp_path, "--stall-timeout", "60")
    stderr = ReadLines(process.stderr)
    wait_for_line(process.stdout, "trial    2/", errors=process.stderr)
    os.kill(child(process, "clnn_ros.nodes.reward"), signal.SIGTERM)
    process.wait(timeout=120)
    text = stderr.text()
    assert process.returncode == 1, text[-3000:]
    assert problem_lines(text) == [
        "run_all: error: node 'reward' exited with status 0 before the episode ended"], \
        text[-3000:]
    assert not processes_with(str(tmp_path))


@pytest.mark.parametrize("node", PROCESSES)
def test_a_paused_process_is_waited_for(ros_env, tmp_path, node):
    """SIGSTOP for 3 s (below the default stall timeout of 5 s), then SIGCONT: nothing is
    declared dead, the run completes and equals the core."""
    seed, trials, max_steps = 1, 5, 400
    process = subprocess.Popen(
        [sys.executable, "-m", "clnn_ros.run_all", "--seed", str(seed), "--trials", str(trials),
         "--max-steps", str(max_steps), "--out", str(tmp_path)],
        env={**ros_env, "CLNN_TEST_RUN": str(tmp_path)}, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, start_new_session=True)
    wait_for_line(process.stdout, "trial    2/", errors=process.stderr)
    pid = child(process, f"clnn_ros.nodes.{node}")
    os.kill(pid, signal.SIGSTOP)
    time.sleep(3.0)
    os.kill(pid, signal.SIGCONT)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 0, stderr[-3000:]
    assert all("error" not in line for line in problem_lines(stderr)), stderr[-3000:]
    with open(tmp_path / "trials.csv") as f:
        steps = [int(row["steps"]) for row in csv.DictReader(f)]
    assert steps == run_episode(seed, Params(trials=trials, max_steps=max_steps)).steps.tolist()
    assert not processes_with(str(tmp_path))


def test_silent_node_is_named_after_the_stall_timeout(ros_env, tmp_path):
    """Alive but publishing nothing: the stall watchdog names it."""
    process = start_run(ros_env, tmp_path, "--stall-timeout", "1",
                        "--env-node", f"python {BROKEN} mute")
    _, stderr = process.communicate(timeout=HANG_S)
    assert process.returncode == 1
    assert problem_lines(stderr) == ["run_all: error: stall: node 'environment' went silent at "
                                   "tick 50 (no progress for 1 s)"]
    # each node downstream says where it stood: at tick 50, without its state
    for node in ("encoder", "reward", "agent"):
        assert f"[{node}]: the episode ended (stall: node 'environment' went silent at tick 50 " \
               f"(no progress for 1 s)) with this node at tick 50, holding none of its inputs" \
               in stderr, stderr[-3000:]
    assert assert_every_tick(raw_messages(tmp_path / "bag")) == 49
    assert not processes_with(str(tmp_path))


@pytest.mark.parametrize("bug, refused", [
    ("wrong_tick", "tick 3: expected tick 2"),
    ("extra_value", "tick 2: 5 values, the task cartpole has 4 variables (cart_position, "
                    "cart_velocity, pole_angle, pole_angular_velocity)"),
])
def test_a_bad_observation_is_blamed_on_its_sender(ros_env, tmp_path, bug, refused):
    """The environment publishes the observation of tick 2 as tick 3, or with one value more
    than its task's variables: every receiver refuses it (the encoder and the trial manager each
    read the task), and the environment (not the encoder downstream) is named."""
    process = start_run(ros_env, tmp_path, "--stall-timeout", "1",
                        "--env-node", f"python {BROKEN} {bug}")
    _, stderr = process.communicate(timeout=HANG_S)
    assert process.returncode == 1
    assert problem_lines(stderr) == [
        f"run_all: error: stall: node 'environment' went silent at tick 2 (no progress for 1 s; "
        f"last refused env/observation: {refused})"], stderr[-3000:]


@pytest.mark.parametrize("trials", [3, 20])
def test_a_renamed_environment_node_is_named_as_such_at_any_length(ros_env, tmp_path, trials):
    """An environment node of one's own, renamed (-r __node:=brain), that announces itself as
    the environment without checking its name (issue 47: 3 trials completed with exit 0, 20
    ended as a foreign publisher): the graph does not start, and the line says why."""
    node = Path(__file__).parents[1] / "examples" / "noisy_cartpole.py"
    run = subprocess.run(
        [sys.executable, "-m", "clnn_ros.run_all", "--trials", str(trials), "--out",
         str(tmp_path), "--env-node", f"python {node} --ros-args -r __node:=brain"],
        env={**ros_env, "CLNN_TEST_RUN": str(tmp_path)}, capture_output=True, text=True,
        timeout=HANG_S)
    assert run.returncode == 1, run.stderr[-3000:]
    assert problem_lines(run.stderr) == [
        "run_all: error: no node named 'environment' in namespace /: node 'brain' (namespace /) "
        "publishes env/observation, env/task; the graph takes an environment node by its name "
        "(renamed, -r __node:=brain, it is none: docs/ENV_CONTRACT.md)"], run.stderr[-3000:]
    assert not (tmp_path / "trials.csv").exists() or \
        len((tmp_path / "trials.csv").read_text().splitlines()) == 1
    assert not processes_with(str(tmp_path))


@pytest.mark.parametrize("command", ["python no_such_file_clnn.py", f"python {BROKEN} crash"],
                         ids=["missing", "raises"])
def test_a_node_that_fails_at_start_ends_the_run_at_once(ros_env, tmp_path, command):
    """Known by its exit (the line names the status), not by a wait for readiness; no time is
    asserted, since a loaded machine takes its time starting Python and ROS."""
    run = subprocess.run(
        [sys.executable, "-m", "clnn_ros.run_all", "--out", str(tmp_path), "--env-node",
         command], env={**ros_env, "CLNN_TEST_RUN": str(tmp_path)}, capture_output=True,
        text=True, timeout=HANG_S)
    assert run.returncode == 1
    lines = problem_lines(run.stderr)
    assert len(lines) == 1 and lines[0].startswith("run_all: error: ") and \
        "node 'environment' exited with status" in lines[0], run.stderr[-2000:]
    if (tmp_path / "bag").exists():  # the encoder's latched input labels came in first
        assert f"run_all: bag {tmp_path / 'bag'}" in run.stdout, run.stdout
        assert [message[1] for message in raw_messages(tmp_path / "bag")] == [
            names.INPUT_LABELS]
    else:  # nothing was recorded: no bag
        assert "run_all: nothing recorded, no bag" in run.stdout
    assert not processes_with(str(tmp_path))


def test_killing_run_all_ends_its_children(ros_env, tmp_path):
    """SIGKILL of run_all: its nodes end (stdin's end of file), the recorder finishes the bag,
    and the work directory it could not remove (in a temp folder of the test's own) is removed
    by the next run_all, whose own is removed at its end."""
    temp = tmp_path / "temp"
    temp.mkdir()
    marker = {**ros_env, "CLNN_TEST_RUN": str(tmp_path), "TMPDIR": str(temp)}
    process = subprocess.Popen(
        [sys.executable, "-m", "clnn_ros.run_all", "--seed", "1", "--trials", "400", "--out",
         str(tmp_path / "killed")], env=marker, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    wait_for_line(process.stdout, "trial    2/", errors=process.stderr)
    assert len(processes_with(str(tmp_path))) == 7  # run_all, 5 nodes and the recorder
    process.kill()
    _, stderr = process.communicate(timeout=120)
    deadline = time.monotonic() + HANG_S
    while processes_with(str(tmp_path)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not processes_with(str(tmp_path))
    assert raw_messages(tmp_path / "killed" / "bag")  # the recorder finished the bag
    assert "Traceback" not in stderr, stderr
    assert len(list(temp.iterdir())) == 1  # the killed run's work directory
    after = subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--trials", "1",
                            "--no-record", "--quiet"], env=marker, capture_output=True,
                           text=True, timeout=HANG_S)
    assert after.returncode == 0, after.stderr
    assert not list(temp.iterdir())


def test_a_second_graph_on_the_same_domain_and_namespace_is_refused(ros_env, tmp_path):
    first = start_run(ros_env, tmp_path / "first")
    try:
        wait_for_line(first.stdout, "trial    2/", errors=first.stderr)
        second = subprocess.run(
            [sys.executable, "-m", "clnn_ros.run_all", "--out", str(tmp_path / "second")],
            env={**ros_env, "CLNN_TEST_RUN": str(tmp_path / "second")}, capture_output=True,
            text=True, timeout=HANG_S)
        assert second.returncode == 1
        lines = problem_lines(second.stderr)
        assert len(lines) == 1 and lines[0].startswith(
            "run_all: error: another graph runs in namespace / on ROS domain"), second.stderr
        assert not (tmp_path / "second" / "bag").exists()  # it held the other's messages
        # what run_all goes by if it has to end a trial manager hung after its results: this
        # one sent no EPISODE_END, so its recorder is told to stop (not left to wait for one)
        summary = json.loads((tmp_path / "second" / "summary.json").read_text())
        assert (summary["exit_status"], summary["ticks"]) == (names.NOT_STARTED, 0)
        assert first.poll() is None  # the first run goes on
    finally:
        os.killpg(first.pid, signal.SIGINT)
        first.communicate(timeout=HANG_S)
    assert first.returncode == 130
