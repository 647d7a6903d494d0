"""Repeatability and isolation of the real graph, and the graph spread over two hosts.

Every run here happens inside a private network namespace that has lo and one end of a veth link
(clnn_ros.lab.two_hosts.veth_link), so the kernel's packet counter of that link shows whether DDS sent
anything off loopback. Three runs of one seed are bit-identical (results and every recorded
message); with the default settings nothing leaves loopback, with ROS_AUTOMATIC_DISCOVERY_RANGE=
SUBNET (the control) packets do; two graphs started at once on two domain ids do not see each
other; the environment node across the link gives the one-host results (python -m
clnn_ros.lab.two_hosts)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from clnn_ros import bag
from clnn_ros.graph import names
from clnn_ros.core.episode import run_episode
from clnn_ros.core.params import Params
from clnn_ros.graph.names import STATE
from clnn_ros.lab.two_hosts import veth_link

from test_graph import processes_with, read_steps, wait_for_line
from test_recording import assert_every_tick, raw_messages

from conftest import HANG_S, free_domain_id

DOMAIN_IDS = [free_domain_id(), free_domain_id()]
TRIALS, MAX_STEPS = 8, 1500
# A bound against a hang of run_all itself, never a speed bound: a stalled graph ends by itself
# (--stall-timeout 20). Beside 4 CPU hogs and another test, two graphs at once ran at 21 ticks/s
# (7 of their 8 trials in the 120 s this bound once was).
RUN_HANG_S = 3 * HANG_S


def namespaces_missing() -> str | None:
    """Why network namespaces cannot be used here (None: they can)."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    probe = subprocess.run(["unshare", "--net", "true"], capture_output=True, text=True)
    if probe.returncode != 0:
        return f"unshare --net fails: {probe.stderr.strip()}"
    return None


NAMESPACES_MISSING = namespaces_missing()
pytestmark = [pytest.mark.ros,  # every test here starts ROS / DDS (or two_hosts)
              pytest.mark.skipif(NAMESPACES_MISSING is not None,
                                 reason=f"{NAMESPACES_MISSING}: no namespace tests")]


@pytest.fixture(scope="module")
def link():
    with veth_link() as created:
        yield created


@pytest.fixture(scope="module")
def base_env(tmp_path_factory):
    """The caller's environment without any DDS discovery choice, so that run_all's own default
    (clnn_ros/session/rosenv.py) is what is tested."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS")}
    return {**env, "ROS_LOG_DIR": str(tmp_path_factory.mktemp("ros_log"))}


def run_graphs(link, runs) -> int:
    """Start every (out dir, seed, environment) run at once with run_all inside the link's host
    A; wait for all. Returns the packets host A sent on the link meanwhile."""
    sent_before = link.packets(0)[0]
    processes = []
    for out, seed, env in runs:
        with open(out / "run_all.log", "w") as log:  # a file: no pipe to fill while we wait
            processes.append(subprocess.Popen(
                link.exec_prefix(0) + [sys.executable, "-m", "clnn_ros.run_all", "--quiet",
                                       "--seed", str(seed), "--trials", str(TRIALS), "--max-steps",
                                       str(MAX_STEPS), "--stall-timeout", "20", "--out", str(out)],
                env=env, stdout=log, stderr=subprocess.STDOUT))
    deadline = time.monotonic() + RUN_HANG_S
    for process, (out, _, _) in zip(processes, runs):
        try:
            process.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGINT)  # run_all stops its graph and says where it was
            process.wait(timeout=HANG_S)
        assert process.returncode == 0, (out / "run_all.log").read_text()[-3000:]
    return link.packets(0)[0] - sent_before


@pytest.fixture(scope="module")
def default_run(link, base_env, tmp_path_factory):
    out = tmp_path_factory.mktemp("default")
    return out, run_graphs(link, [(out, 1, {**base_env, "ROS_DOMAIN_ID": DOMAIN_IDS[0]})])


@pytest.fixture(scope="module")
def subnet_run(link, base_env, tmp_path_factory):
    out = tmp_path_factory.mktemp("subnet")
    return out, run_graphs(link, [(out, 1, {**base_env, "ROS_DOMAIN_ID": DOMAIN_IDS[0],
                                            "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"})])


@pytest.fixture(scope="module")
def concurrent_runs(link, base_env, tmp_path_factory):
    """Seed 1 on one domain id and seed 2 on another, started at the same time."""
    outs = [tmp_path_factory.mktemp(f"domain_{d}") for d in DOMAIN_IDS]
    sent = run_graphs(link, [(out, seed, {**base_env, "ROS_DOMAIN_ID": domain})
                             for out, seed, domain in zip(outs, (1, 2), DOMAIN_IDS)])
    return outs, sent


def namespaces_of(pid: int) -> set[str]:
    """The network namespaces that the two_hosts process `pid` made and left (its names:
    clnn_<pid><4 hex digits>_a/_b); another test run's are not counted."""
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    name = re.compile(rf"clnn_{pid}[0-9a-f]{{4}}_[ab]$")
    return {line.split()[0] for line in listed.splitlines() if name.match(line.split()[0])}


def two_hosts(*args, env=None, timeout: float) -> subprocess.CompletedProcess:
    """Run two_hosts; assert that it left no network namespace."""
    process = subprocess.Popen([sys.executable, "-m", "clnn_ros.lab.two_hosts", *args], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stdout, stderr = process.communicate(timeout=timeout)
    assert not namespaces_of(process.pid), stderr
    return subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)


def assert_equals_core(out: Path, seed: int):
    core = run_episode(seed, Params(trials=TRIALS, max_steps=MAX_STEPS))
    assert read_steps(out) == core.steps.tolist()
    np.testing.assert_array_equal(np.load(out / "final_weights.npy"), core.final_weights)


def recorded(out: Path) -> dict[str, list]:
    """topic -> [(tick, decoded message's repr)] in the order recorded (one
    publisher per topic). Not the log or publish time: they are the wall clock. Not the CDR bytes
    either: Fast CDR leaves the alignment padding between fields uninitialized, so equal messages
    may differ there. The repr, where a NaN (the cart-pole task's threshold: none) equals itself."""
    from rclpy.serialization import deserialize_message
    by_topic = defaultdict(list)
    for _, topic, tick, _, data, _ in raw_messages(out / "bag"):
        message_type = bag.message_class(names.TOPIC_TYPES[topic])
        by_topic[topic].append((tick, repr(deserialize_message(data, message_type))))
    return dict(by_topic)


def test_default_settings_send_nothing_off_loopback(link, default_run, concurrent_runs):
    shown = subprocess.run(["ip", "-n", link.namespaces[0], "-o", "link", "show"],
                           capture_output=True, text=True, check=True).stdout
    interfaces = {re.match(r"\d+: ([^:@]+)", line).group(1) for line in shown.splitlines()}
    assert interfaces == {"lo", link.devices[0]}  # the counted link is the only way out
    out, sent = default_run
    assert sent == 0
    assert_equals_core(out, 1)
    assert concurrent_runs[1] == 0


def test_subnet_discovery_sends_on_the_link(subnet_run):
    """The control: the same check fails when discovery may leave loopback."""
    out, sent = subnet_run
    assert sent > 0
    assert_equals_core(out, 1)


def test_three_runs_of_a_seed_are_bit_identical(default_run, subnet_run, concurrent_runs):
    """Seed 1 alone, alone with SUBNET discovery, and beside another graph: the same trials, the
    same final weights file and the same recorded messages on every topic."""
    runs = [default_run[0], subnet_run[0], concurrent_runs[0][0]]
    first = recorded(runs[0])
    assert set(first) == set(names.TOPIC_TYPES) and len(first[STATE]) > TRIALS
    for out in runs[1:]:
        assert (out / "trials.csv").read_bytes() == (runs[0] / "trials.csv").read_bytes()
        assert (out / "final_weights.npy").read_bytes() == \
            (runs[0] / "final_weights.npy").read_bytes()
        assert recorded(out) == first


def test_two_graphs_at_once_on_two_domains_do_not_see_each_other(concurrent_runs):
    (seed_1, seed_2), _ = concurrent_runs
    assert_equals_core(seed_1, 1)
    assert_equals_core(seed_2, 2)
    states = []
    for out in (seed_1, seed_2):
        messages = raw_messages(out / "bag")
        assert_every_tick(messages)
        ticks = [m[2] for m in messages if m[1] == STATE]
        assert len(ticks) == len(set(ticks))  # one state per tick: no second graph's
        states.append({m[4] for m in messages if m[1] == STATE})
    assert not states[0] & states[1]  # a sample reaches every reader with the same bytes


def test_environment_on_another_host_equals_one_host(base_env, tmp_path):
    """python -m clnn_ros.lab.two_hosts: the environment node in its own namespace, reached over
    the veth link with SUBNET discovery; both runs equal the core and the link carried every
    tick's state."""
    run = two_hosts("--seed", "1", "--trials", str(TRIALS), "--max-steps", str(MAX_STEPS),
                    "--out", str(tmp_path), env={**base_env, "ROS_DOMAIN_ID": DOMAIN_IDS[0]},
                    timeout=2 * RUN_HANG_S)
    assert run.returncode == 0, run.stderr
    summary = run.stdout.splitlines()[-1]
    assert summary.startswith("two_hosts: equal results"), summary
    for out in (tmp_path / "one_host", tmp_path / "two_hosts"):
        assert_equals_core(out, 1)
    ticks, sent = map(int, re.search(r"(\d+) ticks\).*sent (\d+) and", summary).groups())
    assert sent >= ticks  # each tick's state crossed the link


def test_ctrl_c_across_the_link_removes_everything(base_env, tmp_path):
    """Ctrl-C while the environment node runs in the other namespace: two_hosts exits 130, and
    no process of the run and neither namespace is left."""
    marker = {**base_env, "ROS_DOMAIN_ID": DOMAIN_IDS[1], "CLNN_TEST_RUN": str(tmp_path)}
    stderr_file = tmp_path / "stderr.log"  # a file: no pipe to fill while we read stdout
    with open(stderr_file, "w") as stderr_log:
        process = subprocess.Popen(
            [sys.executable, "-m", "clnn_ros.lab.two_hosts", "--trials", "400", "--max-steps", "10000"],
            env=marker, stdout=subprocess.PIPE, stderr=stderr_log, text=True,
            start_new_session=True)
    try:
        wait_for_line(process.stdout, "environment: ip netns exec", errors=process.stderr)  # the two-host run (first)
        wait_for_line(process.stdout, "trial    2/", errors=process.stderr)  # its episode is under way
    finally:
        os.killpg(process.pid, signal.SIGINT)  # what a terminal does on Ctrl-C
        process.communicate(timeout=HANG_S)
        stderr = stderr_file.read_text()
        print(stderr)  # shown if the waits failed
    assert process.returncode == 130, stderr
    assert "two_hosts: interrupted" in stderr and "Traceback" not in stderr
    assert not processes_with(str(tmp_path))
    assert not namespaces_of(process.pid)


@pytest.mark.parametrize("args, message", [
    (["--nsv", "5"], "nsv must be 1, 2, 3 or 4"),
    (["--seed", "-1"], "seed must be an integer from 0 to 2**32-1"),
    (["--discovery", "carrier-pigeon"], "argument --discovery: invalid choice"),
])
def test_two_hosts_refuses_bad_input_before_any_namespace(args, message):
    run = two_hosts(*args, timeout=120)
    assert run.returncode == 2
    assert run.stderr.startswith("two_hosts: error: ") and message in run.stderr
    assert len(run.stderr.splitlines()) == 1
