"""clnn-reproduce on Ray (--ray, clnn_ros.reproduce.cluster): the units of a sweep or learn run
(a configuration x a block of seeds) run on a Ray instance of this machine or on an existing
cluster, both on 127.0.0.1, with CSVs equal to the local run's byte for byte; a sweep resumes
with only its missing units, after Ctrl-C too; nothing of Ray is left running; bad input is one
line. The store and the unit split are tested without Ray as well."""

from __future__ import annotations

import contextlib
import importlib.util
import ipaddress
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from clnn_ros import batch
from clnn_ros.batch import run_batch
from clnn_ros.core.params import Params
from clnn_ros.reproduce import common
from clnn_ros.reproduce.__main__ import build_parser, main
from clnn_ros.reproduce.common import LocalExecutor, executed_by

from conftest import processes_of_test

ROOT = Path(__file__).resolve().parents[1]
HANG_S = 240  # a bound against a hang, never a speed bound (Ray starts in 3 s idle, 30 s loaded)
SWEEP = ["sweep", "--param", "sigma=128,256", "--nsv", "1", "--seeds", "0-63", "--trials", "128"]
SMALL = ["--param", "sigma=128,256", "--nsv", "1", "--seeds", "0-15", "--trials", "32"]
needs_ray = pytest.mark.skipif(importlib.util.find_spec("ray") is None,
                               reason="Ray is not installed (pip install -e '.[cluster]')")


def csv_files(out: Path) -> dict[str, bytes]:
    return {path.name: path.read_bytes() for path in sorted(out.glob("*.csv"))}


def unit_files(out: Path) -> dict[str, tuple[int, int]]:
    """The stored units: name -> (inode, mtime in ns), which a unit written again changes."""
    return {path.name: (path.stat().st_ino, path.stat().st_mtime_ns)
            for path in sorted((out / "runs").glob("*.npz"))}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listening_addresses(pids: list[int]) -> set:
    """The local addresses on which these processes listen (TCP, IPv4 and IPv6)."""
    inodes = set()
    for pid in pids:
        try:
            for fd in os.listdir(f"/proc/{pid}/fd"):
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
                if target.startswith("socket:["):
                    inodes.add(target[8:-1])
        except OSError:
            continue  # ended meanwhile
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(table) as f:
            for line in f.readlines()[1:]:
                fields = line.split()
                if fields[3] != "0A" or fields[9] not in inodes:  # 0A: LISTEN
                    continue
                raw = bytes.fromhex(fields[1].split(":")[0])
                packed = b"".join(raw[k:k + 4][::-1] for k in range(0, len(raw), 4))
                address = ipaddress.ip_address(packed)
                found.add(getattr(address, "ipv4_mapped", None) or address)
    return found


def signal_each(pids: list[int], signum: int) -> None:
    for pid in pids:
        try:
            os.kill(pid, signum)
        except ProcessLookupError:
            pass  # ended meanwhile


def run_cli(tmp_path: Path, args: list[str], env: dict | None = None, **kwargs):
    """clnn-reproduce in a process of its own, marked as this test's (CLNN_TEST_RUN)."""
    env = {**os.environ, **(env or {}), "CLNN_TEST_RUN": str(tmp_path),
           "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.Popen([sys.executable, "-X", "faulthandler", "-m", "clnn_ros.reproduce",
                             *args], cwd=ROOT,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            **kwargs)


def finished(process: subprocess.Popen) -> tuple[int, str, str]:
    try:
        out, err = process.communicate(timeout=HANG_S)
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGABRT)  # faulthandler: where each thread hangs
        out, err = process.communicate()
        pytest.fail(f"clnn-reproduce hung for {HANG_S} s:\n{err[-8000:]}")
    return process.returncode, out, err


def assert_nothing_left(tmp_path: Path) -> None:
    """No process this test started is running (Ray's too: they carry its CLNN_TEST_RUN)."""
    deadline = time.monotonic() + 10
    while processes_of_test(tmp_path) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert processes_of_test(tmp_path) == []


@pytest.fixture(scope="module")
def warm_engine():
    """The batch engine compiled into numba's cache once, so that the workers load it."""
    run_batch([0], Params(trials=1))


# ---- without Ray -------------------------------------------------------------------------------

def test_a_run_cut_into_units_equals_the_run_in_one_piece():
    """Each seed's episode depends on its seed alone: units of any size give the run's arrays."""
    p, seeds = Params(trials=6, sigma=128), np.arange(3, 14)
    whole = run_batch(seeds, p)
    for block in (1, 4, 8, None):
        arrays = common.run_units([(p, seeds)], "t", block=block)[0]
        for name in common.UNIT_ARRAYS:
            np.testing.assert_array_equal(arrays[name], getattr(whole, name))


class StandIn:
    """Stands for a cluster: runs its units in this process, but with run_batch taken back from
    the cluster (on Ray they run in other processes); notes the seeds of each unit."""
    workers, where = 3, "a stand-in cluster"

    def __init__(self):
        self.units = []

    def run(self, units):
        self.units += [seeds.tolist() for _, seeds in units]
        with batch.distributed(None):
            results = list(LocalExecutor().run(units))
        yield from results


def test_the_experiments_plain_runs_go_to_the_cluster_in_units():
    """What `all --ray` relies on: run_batch(seeds, p), as every experiment calls it, is cut
    into units for the cluster's workers; runs from given weights or angles stay here."""
    p = Params(trials=5)
    local = run_batch(range(7), p)
    stand_in = StandIn()
    with executed_by(stand_in):
        remote = run_batch(range(7), p)
        run_batch([0], p, angles=np.zeros(2), learn=False)
    assert stand_in.units == [[0, 1, 2], [3, 4, 5], [6]]  # 7 seeds over 3 workers
    for name in ("seeds", "initial_angles", "steps", "end_status", "final_weights"):
        np.testing.assert_array_equal(getattr(remote, name), getattr(local, name))
    assert batch._distributor is None and common._executor.where == "this machine"


def test_only_the_missing_units_run_and_the_csvs_equal_a_fresh_run(tmp_path, capsys, monkeypatch):
    fresh, resumed = tmp_path / "fresh", tmp_path / "resumed"
    args = ["sweep", *SMALL]
    assert main([*args, "--out", str(fresh)]) == 0
    assert main([*args[:-4], "--seeds", "0-7", "--trials", "32", "--out", str(resumed)]) == 0
    first = unit_files(resumed)
    assert len(first) == 2  # the block of seeds 0-7 of each configuration
    calls = []
    real_run_batch = common.run_batch
    monkeypatch.setattr(common, "run_batch", lambda seeds, p: calls.append(
        (p.sigma, seeds.tolist())) or real_run_batch(seeds, p))
    capsys.readouterr()
    assert main([*args, "--out", str(resumed)]) == 0
    assert calls == [(128, list(range(8, 16))), (256, list(range(8, 16)))]
    assert "sweep: 4 units" in capsys.readouterr().err
    assert {name: unit_files(resumed)[name] for name in first} == first  # not written again
    assert csv_files(resumed) == csv_files(fresh)
    assert not list((resumed / "runs").glob("*partial*"))


def test_without_ray_it_is_one_line_and_nothing_is_written(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray fails as if not installed
    assert main(["sweep", *SMALL, "--ray", "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install -e '.[cluster]'" in err[0], err
    assert not (tmp_path / "o").exists()


def test_bad_parameters_are_refused_before_ray_starts(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # Ray would say it is missing, were it asked
    for command in (["sweep", "--param", "sigma=128,x"], ["learn", "--option", "sigma=x"]):
        assert main([*command, "--seeds", "0", "--trials", "2", "--ray",
                     "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "sigma must be" in err[0], err
    assert not (tmp_path / "o").exists()


# A stand-in for `ray start --head --block`: fails as Ray's node.py does when its raylet is slower
# than its fixed 30 s (its own last line) as long as the file FAILURES counts down, then starts.
STAND_IN_RAY = """import pathlib, sys, time
count = pathlib.Path(__file__).parents[2] / "FAILURES"
left = int(count.read_text())
if left:
    count.write_text(str(left - 1))
    sys.exit("Exception: The current node timed out during startup. This could happen because "
             "some of the raylet failed to startup or the GCS has become overloaded.")
print("Ray runtime started.", flush=True)
time.sleep(600)
"""


@pytest.mark.parametrize("failures, started", [(0, True), (2, True), (None, False)])
def test_a_local_head_that_ray_gave_up_on_is_started_again(tmp_path, failures, started):
    """Ray gives up on a head whose raylet registers after 30 s (not configurable): beside CPU
    hogs a slow start, not a fault, so LocalHead starts it again within its own bound. Any
    other failure is one line naming the head's logs, at the first try."""
    from clnn_ros.reproduce.cluster import ClusterError, LocalHead
    scripts = tmp_path / "ray" / "scripts"
    scripts.mkdir(parents=True)
    for package in (tmp_path / "ray", scripts):
        (package / "__init__.py").write_text("")
    (scripts / "scripts.py").write_text(STAND_IN_RAY if failures is not None
                                        else 'raise SystemExit("port 6379 is in use")')
    (tmp_path / "FAILURES").write_text(str(failures or 0))
    head = LocalHead(1, {"PYTHONPATH": str(tmp_path)})
    before = set(Path(tempfile.gettempdir()).glob("clnn_ray_*"))
    if started:
        with head:
            assert head.process.poll() is None
        assert (tmp_path / "FAILURES").read_text() == "0"
    else:
        with pytest.raises(ClusterError) as refused:
            head.__enter__()
        message, _, logs = str(refused.value).rstrip(")").partition(" (its logs: ")
        assert message == "cannot start a local Ray head: port 6379 is in use", refused.value
        shutil.rmtree(logs)  # kept for the user, who is told where
    assert head.process is None
    assert set(Path(tempfile.gettempdir()).glob("clnn_ray_*")) == before


def head_processes(temp_dir: str) -> dict[str, int]:
    """{program name: pid} of the processes of a Ray head started in `temp_dir`."""
    found = {}
    for pid in (int(p) for p in os.listdir("/proc") if p.isdigit()):
        try:
            command = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if any(temp_dir.encode() in part for part in command):
            found[os.path.basename(command[0].decode(errors="replace"))] = pid
    return found


@pytest.mark.cluster
@needs_ray
def test_a_local_head_whose_gcs_answers_late_still_starts():
    """A loaded machine can keep a new head's GCS from answering for seconds; Ray's own client
    gives up after 5 s by default (gcs_rpc_server_connect_timeout_s), which ended a suite run on
    a loaded machine with "Failed to connect to GCS". The GCS held stopped for 8 s as it
    starts: the head still comes up."""
    from clnn_ros.reproduce.cluster import LocalHead
    head, outcome = LocalHead(1), []

    def start() -> None:
        try:
            head.__enter__()
            outcome.append("started")
        except Exception as error:
            outcome.append(str(error))
    starting = threading.Thread(target=start)
    starting.start()
    gcs, deadline = None, time.monotonic() + HANG_S
    while gcs is None and starting.is_alive() and time.monotonic() < deadline:
        ours = head_processes(head.temp_dir) if head.temp_dir else {}
        # once the raylet runs, `ray start` asks the GCS for the node: then the GCS stops
        if "raylet" in ours and "gcs_server" in ours:
            gcs = ours["gcs_server"]
            os.kill(gcs, signal.SIGSTOP)
        time.sleep(0.005)
    try:
        assert gcs is not None, outcome
        time.sleep(8.0)
    finally:
        if gcs is not None:
            with contextlib.suppress(ProcessLookupError):  # a head that failed is torn down
                os.kill(gcs, signal.SIGCONT)
        starting.join(HANG_S)
        head.__exit__(None, None, None)
    assert outcome == ["started"]


@pytest.mark.parametrize("ray_args, status, message", [
    (["--ray", "no-port"], 2, "give the head's HOST:PORT"),
    (["--ray", "127.0.0.1:FREE"], 1, "cannot reach the Ray cluster at 127.0.0.1:"),
    (["--workers", "2"], 2, "--workers N goes with --ray"),
    (["--ray", "--workers", "0"], 2, "--workers N goes with --ray, N at least 1"),
])
def test_bad_cluster_input_is_one_line(tmp_path, capsys, ray_args, status, message):
    ray_args = [arg.replace("FREE", str(free_port())) for arg in ray_args]
    for command in (["sweep", *SMALL], ["learn", "--seeds", "0-1", "--trials", "2"]):
        assert main([*command, *ray_args, "--out", str(tmp_path / "o")]) == status
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
        assert "Traceback" not in err[0]
    assert not (tmp_path / "o").exists()


def test_learn_sweep_and_all_take_ray():
    parser = build_parser()
    for command in (["learn"], ["sweep"], ["all"]):
        assert parser.parse_args([*command, "--ray"]).ray == "local"
        assert parser.parse_args([*command, "--ray", "10.0.0.1:6379"]).ray == "10.0.0.1:6379"
        assert parser.parse_args(command).ray is None


# ---- a Ray instance of this machine ----------------------------------------------------------

@pytest.mark.cluster
@needs_ray
@pytest.mark.usefixtures("warm_engine")
def test_ray_equals_local_and_ctrl_c_loses_only_the_units_in_flight(tmp_path):
    local, ray_out = tmp_path / "B", tmp_path / "A"
    assert main([*SWEEP, "--out", str(local)]) == 0

    # Interrupted (Ctrl-C: SIGINT to its process group, as a terminal sends it) once the first
    # units are stored; meanwhile every socket of it and of its Ray listens on 127.0.0.1 only.
    # The driver, which stores the units, is stopped at once, then Ray's processes, while their
    # sockets are looked at (a second or more on a loaded machine, time enough for the rest of
    # the sweep: two fresh-clone suite runs saw it end with 0, not 130); all continue with the
    # SIGINT.
    run = run_cli(tmp_path, [*SWEEP, "--ray", "--workers", "2", "--out", str(ray_out)],
                  start_new_session=True)
    deadline = time.monotonic() + HANG_S
    while not unit_files(ray_out) and run.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    if run.poll() is not None:
        pytest.fail(f"the sweep ended with {run.returncode} before it stored a unit: "
                    f"{run.communicate()[1][-3000:]}")
    os.killpg(run.pid, signal.SIGSTOP)
    processes = processes_of_test(tmp_path)
    signal_each(processes, signal.SIGSTOP)
    listening = listening_addresses(processes)
    stored_at_ctrl_c = len(unit_files(ray_out))
    os.killpg(run.pid, signal.SIGINT)  # delivered as they continue
    signal_each(processes, signal.SIGCONT)
    os.killpg(run.pid, signal.SIGCONT)
    status, _, err = finished(run)
    assert status == 130 and err.strip().endswith("interrupted"), \
        f"{stored_at_ctrl_c} units stored at the Ctrl-C, {len(unit_files(ray_out))} after; {err}"
    assert "Traceback" not in err
    assert listening and all(address.is_loopback for address in listening), listening
    assert_nothing_left(tmp_path)
    stored = unit_files(ray_out)
    assert 0 < len(stored) < 16, "the run ended before Ctrl-C"
    assert not list((ray_out / "runs").glob("*partial*"))

    # Started again: only the missing units run; the CSVs equal the local run's.
    status, out, err = finished(run_cli(tmp_path, [*SWEEP, "--ray", "--workers", "2",
                                                   "--out", str(ray_out)]))
    assert status == 0, err
    assert (f"sweep: 16 units (2 configurations x blocks of up to 8 seeds), {len(stored)} "
            f"stored, {16 - len(stored)} to run on 2 Ray workers of this machine") in err
    assert {name: unit_files(ray_out)[name] for name in stored} == stored
    assert len(unit_files(ray_out)) == 16
    assert csv_files(ray_out) == csv_files(local)
    assert (ray_out / "sweep_summary.md").read_text() == (local / "sweep_summary.md").read_text()
    assert_nothing_left(tmp_path)


# ---- an existing cluster: a head of two workers on 127.0.0.1 ----------------------------------

@pytest.fixture
def loopback_head(tmp_path, warm_engine):
    """A head of 2 CPUs, every port of it on 127.0.0.1, with a token of its own (what --ray
    without an address starts, here started apart: an existing cluster to join by address)."""
    from clnn_ros.reproduce.cluster import LocalHead
    with LocalHead(2, {"CLNN_TEST_RUN": str(tmp_path)}) as head:
        yield head


@pytest.mark.cluster
@needs_ray
def test_learn_on_an_existing_cluster_on_loopback_equals_local(tmp_path, loopback_head):
    local, ray_out = tmp_path / "B", tmp_path / "A"
    learn = ["learn", "--seeds", "0-9", "--trials", "16"]
    assert main([*learn, "--out", str(local)]) == 0
    status, out, err = finished(run_cli(tmp_path, [*learn, "--ray", loopback_head.address,
                                                   "--out", str(ray_out)], loopback_head.environ))
    assert status == 0, err
    assert (f"learn: 2 units (1 configuration x blocks of up to 8 seeds), 0 stored, 2 to run "
            f"on 2 Ray workers at {loopback_head.address}") in err
    assert csv_files(ray_out) == csv_files(local)  # learn_1sv.csv, final_weights_1sv.csv
    for name in ("final_weights", "steps", "end_status", "initial_angles", "seeds"):
        np.testing.assert_array_equal(np.load(ray_out / "final_weights_1sv.npz")[name],
                                      np.load(local / "final_weights_1sv.npz")[name])
    listening = listening_addresses(processes_of_test(tmp_path))  # the head's, still up
    assert listening and all(address.is_loopback for address in listening), listening
    loopback_head.__exit__(None, None, None)
    assert_nothing_left(tmp_path)
