"""Units of work (clnn_ros.reproduce.common.run_units) run on a Ray cluster: `--ray [ADDRESS]`.

Without an address a Ray head of this machine's own (LocalHead: every port of it on 127.0.0.1, a
token of its own, ended with the command); with one an existing cluster (`ray start --head` on
one machine, `ray start --address HEAD:PORT` on the others, docs/CLUSTER.md). Either way this
process joins it as a driver and starts one worker per CPU (or --workers): a Ray actor that
loads the compiled batch engine once (numba's cache) and then runs unit after unit, one thread
each; the driver stores each unit as it comes back. Ray is an optional extra (pip install -e
'.[cluster]'); nothing here imports it before a run asks for it.
"""

from __future__ import annotations

import ctypes
import importlib.util
import ipaddress
import logging
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from contextlib import ExitStack, contextmanager

import numpy as np

from ..core.params import Params

CONNECT_TIMEOUT_S = 5.0  # to reach a cluster's head before Ray is asked to join it
PROBE_S = 60.0  # for a process of its own to join the cluster and leave (about 3 s when it does)
PROBE = ("import logging, sys, ray\n"
         "try:\n"
         "    ray.init(address=sys.argv[1], log_to_driver=False, logging_level=logging.CRITICAL)\n"
         "except Exception as error:\n"
         "    sys.exit(str(error).strip().splitlines()[0] if str(error).strip() else repr(error))\n"
         "ray.shutdown()\n")
PROBE_ENV = {"RAY_NUM_REDIS_GET_RETRIES": "1", "RAY_py_gcs_connect_timeout_s": "10",
             "RAY_BACKEND_LOG_LEVEL": "fatal"}  # one try, no C++ log lines
START_S = 180.0  # a bound against a hang for a local head to start (3 s idle, 30 s loaded)
STOP_S = 30.0  # for a local head's processes to end once it is told to stop
WAIT_S = 1.0  # the driver waits for results in slices this long, so that Ctrl-C is seen at once
WORKER_THREADS = 1  # numba threads per worker: a worker per CPU
LOOPBACK_ENVIRON = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}  # this node's address: 127.0.0.1
# A local head's, and its drivers' (+ the token). Ray's clients give a GCS 5 s to answer
# (gcs_rpc_server_connect_timeout_s): a new head's GCS on a loaded machine can take longer, and
# `ray start` then ended a suite run with "Failed to connect to GCS". Slow, not a fault: 60 s,
# within START_S.
LOCAL_ENVIRON = {**LOOPBACK_ENVIRON, "RAY_AUTH_MODE": "token", "RAY_USAGE_STATS_ENABLED": "0",
                 "RAY_gcs_rpc_server_connect_timeout_s": "60"}
# The head's agents get fixed ports: with port 0 the raylet waits for them to write their port in
# a file, and ends the node when that takes over 15 s, as on a loaded machine (ray#65983).
AGENT_PORTS = ("--dashboard-agent-grpc-port", "--dashboard-agent-listen-port",
               "--metrics-export-port", "--runtime-env-agent-port")
STARTED = "Ray runtime started"  # what `ray start` prints once the node is up
# What Ray's node.py raises when its raylet has not registered within a fixed 30 s
# (raylet_start_wait_time_s, not configurable): a slow start on a loaded machine, not a fault.
RAY_STARTUP_TIMED_OUT = "The current node timed out during startup"


class ClusterError(RuntimeError):
    """Ray missing, a cluster not reached, a worker lost: its message is one line for the user."""


def one_line(error: BaseException) -> str:
    text = str(error).strip()
    return (text.splitlines()[0] if text else type(error).__name__)[:300]


def check_reachable(address: str) -> bool:
    """A HOST:PORT address must take a TCP connection within CONNECT_TIMEOUT_S; other forms
    (auto, ray://HOST:PORT) are left to Ray. True for a loopback host."""
    if address == "auto" or "://" in address:
        return False
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"--ray {address}: give the head's HOST:PORT (its ray start --head "
                         f"--port), ray://HOST:PORT or auto")
    host = host.strip("[]")
    try:
        socket.create_connection((host, int(port)), CONNECT_TIMEOUT_S).close()
    except OSError as error:
        raise ClusterError(f"cannot reach the Ray cluster at {address}: "
                           f"{error.strerror or one_line(error)}") from None
    try:
        return ipaddress.ip_address(socket.gethostbyname(host)).is_loopback
    except (OSError, ValueError):
        return False


def probe_join(address: str, environ: dict) -> None:
    """A process of its own joins the cluster at `address` and leaves, within PROBE_S: Ray
    itself would retry for minutes where something else listens, or say so in many lines."""
    try:
        probe = subprocess.run([sys.executable, "-c", PROBE, address], env={**environ, **PROBE_ENV},
                               capture_output=True, text=True, timeout=PROBE_S)
    except subprocess.TimeoutExpired:
        raise ClusterError(f"no Ray cluster answers at {address} within {PROBE_S:g} s (give the "
                           f"head's ray start --head --port)") from None
    if probe.returncode != 0:
        last = [line for line in probe.stderr.splitlines() if line.strip()][-1:] or ["?"]
        raise ClusterError(f"cannot join the Ray cluster at {address}: {last[0].strip()[:300]}")


def check_ray_installed() -> None:
    try:
        found = importlib.util.find_spec("ray") is not None
    except (ImportError, ValueError):  # ValueError: sys.modules["ray"] is None
        found = False
    if not found:
        raise ClusterError("--ray needs Ray, which is not installed here: "
                           "pip install -e '.[cluster]'")


def free_ports(count: int) -> list[int]:
    """Ports free on 127.0.0.1 now (the kernel's choice; each held until all are chosen)."""
    sockets = [socket.socket() for _ in range(count)]
    try:
        for s in sockets:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in sockets]
    finally:
        for s in sockets:
            s.close()


def end_with_parent() -> None:
    """In a child before it runs: SIGTERM to it when this process ends, however (Linux)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def warm_worker(threads: int) -> None:
    """What a worker does once: its numba threads, and the batch engine loaded from numba's
    cache (compiled into it the first time on a machine) by a one-trial run."""
    import numba

    from ..batch import run_batch
    numba.set_num_threads(threads)
    run_batch([0], Params(trials=1))


def descendants(pid: int) -> list[int]:
    """The processes below `pid` (children, theirs, ...), from /proc; [] without /proc."""
    parents = {}
    for entry in os.listdir("/proc") if os.path.isdir("/proc") else []:
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    parents[int(entry)] = int(f.read().rpartition(")")[2].split()[1])
            except (OSError, ValueError, IndexError):
                continue  # ended meanwhile
    found, frontier = [], [pid]
    while frontier:
        children = [child for child, parent in parents.items() if parent in frontier]
        found += children
        frontier = children
    return found


def running(pid: int) -> bool:
    """Whether the process is there and not a zombie (ended, waiting for its parent to reap it)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rpartition(")")[2].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def end_processes(pids: list[int]) -> None:
    """Wait up to STOP_S for these processes (a local head's, told to stop) to end; kill the
    ones still running then, by their ids."""
    deadline = time.monotonic() + STOP_S
    while any(map(running, pids)) and time.monotonic() < deadline:
        time.sleep(0.05)
    for pid in filter(running, pids):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def worth_restarting(failure: str, time_left_s: float) -> bool:
    """Whether a local head that failed with this last log line is started again: only when Ray
    gave up on a deadline of its own (RAY_STARTUP_TIMED_OUT) and START_S still allows."""
    return RAY_STARTUP_TIMED_OUT in failure and time_left_s > 0


class LocalHead:
    """A Ray head of this machine's own, as a context: `ray start --head --block` on 127.0.0.1
    (Ray takes the loopback address as the node's when it is not to form a cluster: the switch
    its macOS and Windows builds use), `cpus` CPUs, fixed agent ports (AGENT_PORTS), a token of
    its own (no file in ~/.ray; nobody else can join) and a temporary folder of its own. Leaving
    stops it (SIGTERM: Ray ends its processes; any left after STOP_S are killed by their ids);
    it also ends when this process does. A start that Ray gave up on by its own fixed deadline is
    made again while START_S allows (worth_restarting). `environ`: what a driver needs to join it."""

    def __init__(self, cpus: int, extra_environ: dict | None = None):
        self.cpus, self.extra = cpus, extra_environ or {}
        self.environ = {**LOCAL_ENVIRON, "RAY_AUTH_TOKEN": secrets.token_hex(32)}
        self.address = ""
        self.process = None
        self.temp_dir = None

    def __enter__(self) -> "LocalHead":
        deadline = time.monotonic() + START_S
        try:
            while (failure := self._start(deadline)) is not None:
                if not worth_restarting(failure, deadline - time.monotonic()):
                    logs, self.temp_dir = self.temp_dir, None  # kept: what went wrong is there
                    raise ClusterError(f"cannot start a local Ray head: {failure} "
                                       f"(its logs: {logs})")
                self.__exit__(None, None, None)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _start(self, deadline: float) -> str | None:
        """Starts the head and waits until it is up (None) or has failed: its last log line."""
        self.temp_dir = tempfile.mkdtemp(prefix="clnn_ray_")  # short: Ray's socket paths
        gcs, *agents = free_ports(1 + len(AGENT_PORTS))
        self.address = f"127.0.0.1:{gcs}"
        log = os.path.join(self.temp_dir, "head.log")
        with open(log, "wb") as out:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "ray.scripts.scripts", "start", "--head", "--block",
                 f"--port={gcs}", "--node-ip-address=127.0.0.1", f"--num-cpus={self.cpus}",
                 "--include-dashboard=false", "--disable-usage-stats",
                 f"--temp-dir={self.temp_dir}",
                 *(f"{flag}={port}" for flag, port in zip(AGENT_PORTS, agents))],
                env={**os.environ, **self.extra, **self.environ}, stdin=subprocess.DEVNULL,
                stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
                preexec_fn=end_with_parent)
        while True:
            with open(log, errors="replace") as f:
                text = f.read()
            if STARTED in text:
                return None
            if self.process.poll() is not None or time.monotonic() > deadline:
                lines = [line.strip() for line in text.splitlines() if line.strip()]
                return (lines or ["no output"])[-1][:300]
            time.sleep(0.1)

    def __exit__(self, *exc) -> None:
        if self.process is not None:
            below = descendants(self.process.pid)
            if self.process.poll() is None:
                self.process.terminate()
                try:
                    self.process.wait(STOP_S)
                except subprocess.TimeoutExpired:
                    self.process.kill()
                    self.process.wait()
            end_processes(below)
            self.process = None
        if self.temp_dir is not None:
            shutil.rmtree(self.temp_dir, ignore_errors=True)
            self.temp_dir = None


class UnitWorker:
    """A Ray actor: warmed once, then runs units (clnn_ros.reproduce.common.run_unit)."""

    def __init__(self, threads: int):
        warm_worker(threads)

    def run(self, p: Params, seeds: np.ndarray) -> dict:
        from .common import run_unit
        return run_unit(p, seeds)


class RayExecutor:
    """The executor of units on a Ray cluster, as a context: entering joins the cluster at
    `address` (None: starts a LocalHead first) and starts the workers; leaving ends them, leaves
    the cluster (and stops a local head)."""

    def __init__(self, address: str | None = None, workers: int | None = None):
        self.address, self.requested = address, workers
        self.ray = None
        self.actors = []
        self.workers = 0
        self.where = ""
        self.stack = ExitStack()

    def __enter__(self) -> "RayExecutor":
        with ExitStack() as stack:
            check_ray_installed()
            if self.address is None:
                head = stack.enter_context(LocalHead(self.requested or os.cpu_count()))
                stack.enter_context(environ_set(head.environ))
                address, where = head.address, "of this machine"
            else:
                if check_reachable(self.address):  # a head on this machine's loopback: so are we
                    stack.enter_context(environ_set(LOOPBACK_ENVIRON))
                probe_join(self.address, dict(os.environ))
                address, where = self.address, f"at {self.address}"
            import ray  # after the environment is set: Ray reads it once, as it is imported
            self.ray = ray
            try:
                ray.init(address=address, log_to_driver=False, logging_level=logging.ERROR)
                stack.callback(ray.shutdown)
                cpus = int(ray.cluster_resources().get("CPU", 0))
            except Exception as error:
                raise ClusterError(f"cannot join Ray at {address}: {one_line(error)}") from None
            if cpus < 1:
                raise ClusterError(f"the Ray cluster at {address} has no CPU to run on")
            self.workers = self.requested or cpus
            actor = ray.remote(num_cpus=min(1.0, cpus / self.workers))(UnitWorker)
            self.actors = [actor.remote(WORKER_THREADS) for _ in range(self.workers)]
            stack.callback(self.actors.clear)
            self.where = f"{self.workers} Ray workers {where}"
            self.stack = stack.pop_all()
        return self

    def __exit__(self, *exc) -> None:
        self.stack.close()

    def run(self, units: list[tuple[Params, np.ndarray]]):
        """(index in units, arrays) for each unit, as they finish; one unit per idle worker."""
        with ctrl_c_noted() as interrupted:
            yield from self._run(units, interrupted)

    def _run(self, units: list[tuple[Params, np.ndarray]], interrupted: list[int]):
        ray = self.ray
        todo = list(reversed(range(len(units))))
        idle, in_flight = list(self.actors), {}
        while todo or in_flight:
            while todo and idle:
                k, actor = todo.pop(), idle.pop()
                in_flight[actor.run.remote(*units[k])] = (k, actor)
            done, _ = ray.wait(list(in_flight), num_returns=1, timeout=WAIT_S)
            if interrupted:
                raise KeyboardInterrupt
            for ref in done:
                k, actor = in_flight.pop(ref)
                try:
                    arrays = ray.get(ref)
                except ray.exceptions.RayError as error:
                    raise ClusterError(f"a unit failed on the Ray cluster: "
                                       f"{one_line(error)}") from None
                idle.append(actor)
                yield k, arrays


@contextmanager
def ctrl_c_noted():
    """SIGINT noted (in the list yielded) instead of raised: Ray runs Python's signal handlers
    inside its own calls, where the KeyboardInterrupt can be lost (seen in a suite run: a sweep
    that got Ctrl-C with 1 of 16 units stored ran all 16 and exited 0). The driver raises it
    itself between two waits for results."""
    received = []
    previous = signal.signal(signal.SIGINT, lambda number, _frame: received.append(number))
    try:
        yield received
    finally:
        signal.signal(signal.SIGINT, previous)


@contextmanager
def environ_set(values: dict):
    """These environment variables set (for Ray, and the processes it starts) within."""
    before = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in before.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
