"""The graph's one transport: UDP on the loopback interface (clnn_ros/session/rosenv.py,
fastdds_loopback.xml). While a run goes on, none of its processes maps a Fast DDS shared-memory
file and every UDP socket they hold is bound to 127.0.0.1; a stock ROS 2 process (ROS's own
defaults: shared memory and UDP) receives the graph's spikes, under LOCALHOST and under SUBNET
(ROS's default; in a network namespace with loopback alone, so its multicast goes nowhere)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from test_graph import processes_with, wait_for_line

from conftest import HANG_S, free_domain_id, ros_environment

pytestmark = pytest.mark.ros  # every test here starts ROS / DDS
DOMAIN_ID = free_domain_id()
LISTENER = Path(__file__).with_name("stock_listener.py")
LOOPBACK = "0100007F"  # 127.0.0.1 as /proc/net/udp writes it


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)


def udp_sockets(pid: int) -> list[str]:
    """The local addresses (hex, as /proc/net/udp writes them) of the UDP sockets of `pid`."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except FileNotFoundError:
            continue  # closed since the listing
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    addresses = []
    for table in ("udp", "udp6"):
        with open(f"/proc/{pid}/net/{table}") as lines:
            addresses += [fields[1] for fields in map(str.split, list(lines)[1:])
                          if fields[9] in inodes]
    return addresses


def fast_dds_mappings(pid: int) -> set[str]:
    with open(f"/proc/{pid}/maps") as maps:
        return {line.split()[-1] for line in maps if "/dev/shm/fastrtps" in line}


@pytest.mark.parametrize("discovery_range, composed", [("LOCALHOST", False), (None, True)],
                         ids=["LOCALHOST, processes", "unset, composed"])
def test_every_process_of_a_run_talks_udp_on_loopback_alone(ros_env, tmp_path, discovery_range,
                                                            composed):
    env = {**ros_env, "CLNN_TEST_RUN": str(tmp_path)}
    if discovery_range is None:
        del env["ROS_AUTOMATIC_DISCOVERY_RANGE"]
    process = subprocess.Popen(
        [sys.executable, "-m", "clnn_ros.run_all", "--seed", "1", "--trials", "400", "--out",
         str(tmp_path), *(["--composed"] if composed else [])], env=env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        wait_for_line(process.stdout, "trial    2/", errors=process.stderr)
        sockets = {pid: udp_sockets(pid) for pid in processes_with(str(tmp_path))}
        mapped = {pid: fast_dds_mappings(pid) for pid in sockets}
    finally:
        os.killpg(process.pid, signal.SIGINT)
        _, stderr = process.communicate(timeout=HANG_S)
    assert process.returncode == 130, stderr[-3000:]
    # run_all (the nodes' process when composed), the recorder, and the five nodes' processes
    assert len(sockets) == (2 if composed else 7), sockets
    assert sum(bool(held) for held in sockets.values()) == (2 if composed else 6), sockets
    assert all(address.startswith(LOOPBACK + ":") for held in sockets.values()
               for address in held), sockets
    assert not any(mapped.values()), mapped


def namespaces_missing() -> str | None:
    """Why a private network namespace cannot be made here (None: it can)."""
    probe = subprocess.run(["unshare", "--net", "true"], capture_output=True, text=True)
    return None if probe.returncode == 0 else f"unshare --net fails: {probe.stderr.strip()}"


# The graph and the stock listener in a network namespace of their own, loopback alone.
IN_NAMESPACE = """ip link set lo up
"$PYTHON" -m clnn_ros.run_all --quiet --no-record --seed 1 --trials 400 --out "$OUT" > /dev/null \
    2> "$OUT/run_all.err" &
graph=$!
env -u FASTRTPS_DEFAULT_PROFILES_FILE -u ROS_AUTOMATIC_DISCOVERY_RANGE $STOCK \
    "$PYTHON" "$LISTENER" 300 120
kill -INT $graph
wait $graph
"""


@pytest.mark.skipif(namespaces_missing() is not None, reason="no network namespaces here")
@pytest.mark.parametrize("stock_range", ["LOCALHOST", "SUBNET"])
def test_a_stock_ros_process_receives_the_spikes(ros_env, tmp_path, stock_range):
    env = {key: value for key, value in ros_env.items()
           if key not in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "FASTRTPS_DEFAULT_PROFILES_FILE")}
    stock = f"ROS_AUTOMATIC_DISCOVERY_RANGE={stock_range}" if stock_range != "SUBNET" else ""
    run = subprocess.run(
        ["unshare", "--net", "sh", "-c", IN_NAMESPACE],
        env={**env, "CLNN_TEST_RUN": str(tmp_path), "PYTHON": sys.executable,
             "OUT": str(tmp_path), "LISTENER": str(LISTENER), "STOCK": stock},
        capture_output=True, text=True, timeout=HANG_S)
    ticks = [int(tick) for tick in run.stdout.split()]
    assert len(ticks) == 300, (run.stdout, run.stderr[-3000:])
    assert ticks == sorted(set(ticks)), ticks  # each tick once, in order
    assert run.returncode == 130, (tmp_path / "run_all.err").read_text()[-3000:]


def test_the_participant_lease_the_trial_manager_waits_for_is_the_profiles():
    """GraphClaim.patience waits a lease for another graph's nodes to leave: the profiles'."""
    import xml.etree.ElementTree as ElementTree

    from clnn_ros.session.rosenv import LOOPBACK_PROFILE, PARTICIPANT_LEASE_S, SUBNET_PROFILE
    for profile in (LOOPBACK_PROFILE, SUBNET_PROFILE):
        leases = [float(element.findtext("{*}sec")) for element in
                  ElementTree.parse(profile).iter("{http://www.eprosima.com/XMLSchemas/"
                                                  "fastRTPS_Profiles}leaseDuration")]
        assert leases == [PARTICIPANT_LEASE_S], profile
