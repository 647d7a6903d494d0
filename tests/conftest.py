"""Session-wide test fixtures, and ROS domains of the tests' own."""

import csv
import errno
import fcntl
import os
import re
import socket
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from clnn_ros.session.process_signals import SHOW_STACKS


# The longest test files, longest first (seconds per file in a suite run, scripts/test.sh
# --durations=0): scripts/test.sh gives whole files to two workers as they become free, so the
# long ones go first and the short ones even out the end. The other files follow in their order.
LONGEST_FIRST = ("test_faults", "test_recording", "test_graph", "test_isolation", "test_load",
                 "test_batch", "test_env_contract", "test_fuzz", "test_leaks", "test_checkpoint",
                 "test_ros_interface", "test_echo")


def pytest_collection_modifyitems(items):
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.stem, len(rank)))  # stable: files stay whole


@pytest.fixture(scope="session")
def in_private_shm() -> list[str]:
    """A command prefix that runs a command with a /dev/shm of its own (only its files are
    there), or [] where mount namespaces are not allowed."""
    prefix = ["unshare", "--mount", "sh", "-c", 'mount -t tmpfs tmpfs /dev/shm && exec "$@"', "_"]
    allowed = subprocess.run([*prefix, "true"], capture_output=True).returncode == 0
    return prefix if allowed else []


# run_all's line for a node that ended neither by itself nor on SIGTERM after the episode (its
# results and messages complete): hung in native code with Python's lock held, as Fast DDS 2.14's
# participant deletion does now and then (docs/ROS_GRAPH.md). A node that missed its end would
# still stop on SIGTERM ("terminated"), which no test allows.
HUNG_IN_NATIVE = re.compile(r"^run_all: warning: node \w+ did not exit in time, nor on SIGTERM ")
# Before it terminates a node, run_all shows its stacks under this line; the verdict follows.
STACKS = re.compile(r"^run_all: node \w+ is slow to exit; the stacks of its threads:$")


def tool(env, module, *args) -> subprocess.CompletedProcess:
    """A tool's run, with a bound against a hang; a hung tool shows the stack of each of its
    threads (process_signals.SHOW_STACKS; seen once, in fa5: echo --once printed nothing,
    not even its error after --wait 60)."""
    process = subprocess.Popen([sys.executable, "-m", module, *args], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        stdout, stderr = process.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        process.send_signal(SHOW_STACKS)
        time.sleep(1.0)  # for the stacks to be written
        process.kill()
        stdout, stderr = process.communicate()
        raise AssertionError(f"{module} {' '.join(args)} hung; stdout {stdout!r}; stderr "
                             f"with its threads' stacks:\n{stderr}") from None
    return subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)


def problem_lines(stderr: str) -> list[str]:
    """run_all's error and warning lines, but for a node hung in native code on its way out."""
    return [line for line in stderr.splitlines() if line.startswith("run_all:")
            and not HUNG_IN_NATIVE.match(line) and not STACKS.match(line)]


# The two wait files of LTTng (lttng-ust-wait-6, lttng-ust-wait-6-<uid>): every process that
# loads ROS's tracetools (rclpy does) maps them, and LTTng keeps them for the next one; the
# only files in /dev/shm that a run or test of the project makes (DDS runs over UDP).
LTTNG_WAIT = re.compile(r"lttng-ust-wait-\d+(-\d+)?")


def not_lttng(names) -> list[str]:
    """Those of these /dev/shm file names that are not LTTng's wait files."""
    return sorted(name for name in names if not LTTNG_WAIT.fullmatch(name))


# A bound against a hang, never a speed bound: a graph's start and end took over 60 s beside a
# second suite run and CPU hogs (load 11 on 2 cores).
HANG_S = 180

# 0 is everyone's default. A domain's ports are 7400 + 250 x domain + 10 to + 73 (participants
# 0-31): up to domain 101 they stay below Linux's ephemeral range (32768-60999), where any
# process's outgoing socket may take a port a participant of the domain then cannot bind.
DOMAINS = range(1, 102)
LOCKS = "/tmp/clnn_ros_test_domains"
_held = []  # the lock files this test process holds (released when it exits)


def free_domain_id() -> str:
    """A ROS domain that no other run on this machine uses: one whose lock file no other test
    process holds and on which no DDS participant listens (Fast DDS gives a domain's first
    participant the UDP port 7410 + 250 x domain; a taken port means the domain is in use)."""
    os.makedirs(LOCKS, exist_ok=True)
    start = os.getpid() % len(DOMAINS)
    for offset in range(len(DOMAINS)):
        domain = DOMAINS[(start + offset) % len(DOMAINS)]
        lock = open(os.path.join(LOCKS, f"{domain}.lock"), "w")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        if port_in_use(7410 + 250 * domain):
            lock.close()
            continue
        _held.append(lock)
        return str(domain)
    raise RuntimeError(f"no free ROS domain in {DOMAINS}")


def port_in_use(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("0.0.0.0", port))
        except OSError as error:
            return error.errno == errno.EADDRINUSE
    return False


def ros_environment(domain_id: str, tmp_path_factory) -> dict:
    """The environment of a test module's ROS processes: its own domain, loopback discovery,
    ROS logs in a temporary folder."""
    return {**os.environ, "ROS_DOMAIN_ID": domain_id, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "ROS_LOG_DIR": str(tmp_path_factory.mktemp("ros_log"))}


def assert_run_equals_episode(out: Path, episode) -> None:
    """A run's out folder (trials.csv, final_weights.npy) holds the core episode's successful
    steps, trial by trial, and its final weights."""
    with open(out / "trials.csv") as f:
        assert [int(row["steps"]) for row in csv.DictReader(f)] == episode.steps.tolist()
    np.testing.assert_array_equal(np.load(out / "final_weights.npy"), episode.final_weights)


def processes_of_test(tmp_path) -> list[int]:
    """PIDs of the processes a test started with CLNN_TEST_RUN set to its tmp_path or a folder
    below it."""
    mark, found = f"CLNN_TEST_RUN={tmp_path}".encode(), []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/environ", "rb") as environ:
                entries = environ.read().split(b"\0")
        except OSError:
            continue  # ended meanwhile, or not ours to read
        if any(entry == mark or entry.startswith(mark + b"/") for entry in entries):
            found.append(int(pid))
    return found


@pytest.fixture(autouse=True)
def stop_what_the_test_left_running(tmp_path):
    """A test that failed half-way leaves its run going; on the module's domain the next test's
    run would then be refused as a second graph (and fail for that). So after each test, what
    it left is interrupted (Ctrl-C), and killed if it is still there 30 s later."""
    yield
    for signum, wait_s in ((signal.SIGINT, 30.0), (signal.SIGKILL, 10.0)):
        pids = processes_of_test(tmp_path)
        for pid in pids:
            try:
                os.kill(pid, signum)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + wait_s
        while pids and processes_of_test(tmp_path) and time.monotonic() < deadline:
            time.sleep(0.1)
