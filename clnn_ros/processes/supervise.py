"""run_all's processes, the graph's nodes and the recorder: started, watched and stopped by
their owner, so that a child that exits is known at once (its exit status or signal and the
last lines of its stderr), never guessed from silence; and the children end when run_all ends,
even killed with SIGKILL.

Each child gets a pipe on stdin that run_all never writes to (a node sees its end of file when
run_all is gone: process_signals.EXIT_WITH_STDIN) and its stderr is read by a thread that passes
each line on to run_all's stderr and keeps the last ones. The run's work directory is locked
while run_all lives: one left by a killed run_all is removed by the next run_all.
"""

from __future__ import annotations

import fcntl
import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from pathlib import Path
from typing import Callable

from ..graph.names import GRAPH_NODES, RECORDER, TRIAL_MANAGER
from ..graph.run import node_arguments, write_params
from ..session.process_signals import EXIT_WITH_STDIN, SHOW_STACKS

NODES = (*GRAPH_NODES, TRIAL_MANAGER)
# After the episode ends or Ctrl-C, how long the nodes get to exit by themselves, and then the
# recorder to finish the bag (it may lag on a loaded machine): then they are terminated.
SHUTDOWN_GRACE_S = 10.0
RECORDER_GRACE_S = 30.0
TAIL_LINES = 5
_STDERR = threading.Lock()
# A node whose Python code runs stops within this of SIGTERM: its spin loop's 0.1 s, the wait
# for its last messages' acknowledgements (nodes.glue.ACK_WAIT_S, 2 s: a killed subscriber
# never acknowledges) and its participant's deletion.
TERMINATE_S = 5.0
STACKS_S = 0.5  # for a child's stacks (SHOW_STACKS) to reach its stderr
# "<prog>: error: <message>" (the project's one-line errors) or a ROS log line at ERROR.
OWN_ERROR = re.compile(r"^(?:\S+: error: |\[ERROR\] \[[\d.]+\] \[[^\]]+\]: )(.*)$")


def waited_for_cpu_s(pid: int) -> float:
    """Seconds the main thread of process `pid` has been ready to run but waiting for a CPU
    (/proc/PID/schedstat; 0 where it cannot be read)."""
    try:
        with open(f"/proc/{pid}/schedstat") as schedstat:
            return int(schedstat.read().split()[1]) / 1e9
    except (OSError, ValueError, IndexError):
        return 0.0


def stopped(pid: int) -> bool:
    """Whether process `pid` is stopped (SIGSTOP, Ctrl-Z, a debugger: /proc/PID/stat state T or
    t): alive, and not running until someone continues it."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rpartition(")")[2].split()[0] in ("T", "t")
    except (OSError, IndexError):
        return False


class Grace:
    """The time a child has had since this began: the wall time less what its main thread
    spent waiting for a CPU and the time it was seen stopped (looked at on each elapsed()). A
    child starved on a loaded machine is slow, not hung: a suite beside CPU hogs saw a trial
    manager take over SHUTDOWN_GRACE_S of wall time to exit after its results were written
    (run fh1), with none of that time its own; and a recorder stopped past the grace was
    terminated once continued instead of finishing its bag (issue 37)."""

    def __init__(self, pid: int):
        self.pid, self.began, self.waited = pid, time.monotonic(), waited_for_cpu_s(pid)
        self.looked_at, self.stopped_s, self.seen_stopped = self.began, 0.0, False

    def elapsed(self) -> float:
        now = time.monotonic()
        if stopped(self.pid):
            self.stopped_s += now - self.looked_at
            self.seen_stopped = True
        self.looked_at = now
        return now - self.began - self.stopped_s - (waited_for_cpu_s(self.pid) - self.waited)


def exit_description(name: str, returncode: int) -> str:
    """A node's exit as run_all and launch say it: `node 'x' exited with status 3`, `node 'x'
    died (SIGKILL)`, or for status 0 (a failure only before the episode's end) `node 'x'
    exited with status 0 before the episode ended`."""
    if returncode < 0:
        return f"node '{name}' died ({signal.Signals(-returncode).name})"
    return f"node '{name}' exited with status {returncode}" + (
        " before the episode ended" if returncode == 0 else "")


def say(line: str) -> None:
    """One whole line on run_all's stderr (the children's stderr readers write there too)."""
    with _STDERR:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()


class Child:
    """One process of the run."""

    def __init__(self, name: str, command: list[str], env: dict, shows_stacks: bool):
        self.name = name
        self.shows_stacks = shows_stacks  # on SHOW_STACKS (process_signals.catch_signals)
        self.tail = deque(maxlen=TAIL_LINES)
        # the time it was seen stopped (SIGSTOP): look_whether_stopped, Supervisor.stop
        self.stopped_s, self._looked_at = 0.0, time.monotonic()
        self.process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE,
                                        env=env)
        self._reader = threading.Thread(target=self._pass_stderr, daemon=True,
                                        name=f"stderr-{name}")
        self._reader.start()

    def _pass_stderr(self) -> None:
        for line in iter(self.process.stderr.readline, b""):
            text = line.decode(errors="replace").rstrip("\n")
            self.tail.append(text)
            try:
                say(text)
            except (OSError, ValueError):
                pass  # run_all's own stderr is gone: keep draining the child's

    @property
    def returncode(self) -> int | None:
        return self.process.poll()

    def describe_exit(self) -> str:
        """exit_description, or the child's own last error line first ('disk full writing F
        (node 'recorder' exited with status 1)')."""
        exit_line = exit_description(self.name, self.process.returncode)
        own = self.own_error()
        return f"{own} ({exit_line})" if own else exit_line

    def own_error(self) -> str | None:
        """The message of the child's last error line, if it wrote one."""
        self._reader.join(timeout=1.0)  # its last lines
        return next((m.group(1) for m in map(OWN_ERROR.match, reversed(self.tail)) if m), None)

    def look_whether_stopped(self) -> None:
        now = time.monotonic()
        if stopped(self.process.pid):
            self.stopped_s += now - self._looked_at
        self._looked_at = now

    def last_lines(self) -> list[str]:
        return list(self.tail)

    def signal(self, signum: int) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signum)

    def wait(self, timeout: float) -> bool:
        try:
            self.process.wait(timeout=max(0.0, timeout))
            return True
        except subprocess.TimeoutExpired:
            return False

    def wait_while(self, allowed: Callable[[], bool]) -> bool:
        """Whether it ended while `allowed()` held (looked at every 0.1 s)."""
        while allowed():
            if self.wait(0.1):
                return True
        return self.wait(0.0)

    def close(self) -> None:
        self._reader.join(timeout=1.0)
        for stream in (self.process.stdin, self.process.stderr):
            try:
                stream.close()
            except OSError:
                pass


class Supervisor:
    """The children of one run."""

    def __init__(self):
        self.children: dict[str, Child] = {}

    def start(self, name: str, command: list[str], env: dict, shows_stacks: bool = False) -> Child:
        """A child; `shows_stacks`: it prints its stacks on SHOW_STACKS (a node of this package,
        not an --env-node command of one's own, on which the signal could end the process)."""
        self.children[name] = child = Child(name, command, env, shows_stacks)
        return child

    def first_failure(self, exclude: set[str]) -> Child | None:
        """A child (not in `exclude`) that exited with a non-zero status or a signal."""
        return next((c for name, c in self.children.items() if name not in exclude
                     and c.returncode not in (None, 0)), None)

    def stop(self, names: list[str], grace_s: float, interrupt: bool) -> list[tuple[str, str]]:
        """Stop these children: told with SIGTERM first if `interrupt` (a node takes it as it
        takes SIGINT, docs/ENV_CONTRACT.md, and one still importing its modules ends silently,
        where SIGINT would print a KeyboardInterrupt traceback), else they get `grace_s` to exit
        by themselves; then SIGTERM again, then SIGKILL. Returns (name, "terminated" or
        "killed") for each child it had to stop: killed if it did not end on SIGTERM either (a
        process hung in native code with Python's lock held cannot run its signal handler)."""
        chosen = [self.children[n] for n in names if n in self.children]
        if interrupt:
            for child in chosen:
                child.signal(signal.SIGTERM)
        graces = [Grace(child.process.pid) for child in chosen]
        forced = []
        for child, grace in zip(chosen, graces):
            told = []

            def allowed() -> bool:
                within = grace.elapsed() < grace_s
                if grace.seen_stopped and not told:
                    told.append(child.name)
                    say(f"run_all: node {child.name} is stopped (SIGSTOP?): waiting for it to "
                        f"continue (kill -CONT {child.process.pid})")
                return within
            ended = child.wait_while(allowed)
            child.stopped_s += grace.stopped_s
            if ended:
                continue
            if child.shows_stacks:  # where it hangs, in the run's log
                say(f"run_all: node {child.name} is slow to exit; the stacks of its threads:")
                child.signal(SHOW_STACKS)
                child.wait(STACKS_S)
            child.signal(signal.SIGTERM)
            if child.wait(TERMINATE_S):
                forced.append((child.name, "terminated"))
                continue
            forced.append((child.name, "killed"))
            child.signal(signal.SIGKILL)
            child.wait(5.0)
        return forced

    def close(self) -> None:
        for child in self.children.values():
            child.close()


WORKDIR_PREFIX = "clnn_ros_run_"
_WORKDIR_LOCK = ".owner.lock"


@contextlib.contextmanager
def work_directory():
    """A run's temporary directory, removed at the end; locked (flock) while this process lives,
    so that one left by a killed run_all (SIGKILL runs no clean-up) is known by its free lock
    and removed here. The lock is taken before the lock file gets its name: a directory without
    it is one still being set up."""
    for abandoned in Path(tempfile.gettempdir()).glob(f"{WORKDIR_PREFIX}*/{_WORKDIR_LOCK}"):
        try:
            with open(abandoned) as lock:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                shutil.rmtree(abandoned.parent, ignore_errors=True)
        except OSError:
            continue  # its run_all lives (or it is another user's)
    directory = Path(tempfile.mkdtemp(prefix=WORKDIR_PREFIX))
    with open(directory / "setting_up", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        os.rename(directory / "setting_up", directory / _WORKDIR_LOCK)
        try:
            yield directory
        finally:
            shutil.rmtree(directory, ignore_errors=True)


# --- the graph's processes -------------------------------------------------------------

def child_environment() -> dict:
    return {**os.environ, EXIT_WITH_STDIN: "1"}


def run_separate(supervisor: Supervisor, values: dict, workdir: Path,
                 env_command: list[str] | None, namespace: str,
                 interrupted: list[int], began: float,
                 bag_path: Path | None) -> tuple[int, str | None]:
    """Start the nodes (env_command None: no environment) and watch them until the trial
    manager ends. Returns (its exit status, or 128 + signal; the failure run_all saw itself, or
    None: a process that exited with an error or a signal, or that someone else stopped before
    the episode ended; one seen before a Ctrl-C stays, as what ended the run)."""
    arguments = node_arguments(write_params(workdir / "params.yaml", values), namespace)
    for name in NODES:
        command = env_command if name == "environment" else \
            [sys.executable, "-m", f"clnn_ros.nodes.{name}"]
        if command is not None:
            supervisor.start(name, [*command, *arguments], child_environment(),
                             shows_stacks=command[:2] == [sys.executable, "-m"] and
                             command[2].startswith("clnn_ros."))
    manager = supervisor.children[TRIAL_MANAGER]
    failure, ended, outcome, status, since_quit = None, None, None, None, None
    recorder = supervisor.children.get(RECORDER)
    while manager.returncode is None and not interrupted:
        if failure := supervisor.first_failure(exclude={TRIAL_MANAGER}):
            break
        if recorder is not None:  # what a stopped recorder misses, run_all says why
            recorder.look_whether_stopped()
        if ended is None and (outcome := fresh_summary(Path(values["out_dir"]), began)):
            ended = Grace(manager.process.pid)  # the episode is over and its results written
        # A node ends with status 0 after the episode's end, or when someone else stopped it
        # (SIGINT, SIGTERM): then the trial manager, which has not ended, never will. It sends
        # the end before it writes the results: a starved one may take long to write them.
        quitter = next((c for name, c in supervisor.children.items()
                        if name in NODES and c.returncode == 0), None)
        since_quit = (since_quit or Grace(manager.process.pid)) \
            if quitter and ended is None else None
        if since_quit is not None and since_quit.elapsed() > SHUTDOWN_GRACE_S:
            failure = quitter
            break
        if ended is not None and ended.elapsed() > SHUTDOWN_GRACE_S:
            # Its DDS participant hangs in deletion (seen once: Fast DDS 2.14's
            # DomainParticipant::set_listener spins while a discovery callback waits for a lock
            # it holds, with the GIL held, so no signal handler runs): nothing is lost by
            # ending it now.
            warn_forced(supervisor.stop([TRIAL_MANAGER], 0.0, interrupt=False))
            # its own status: NOT_STARTED sent no EPISODE_END (the recorder is told to finish)
            status = outcome["exit_status"]
            break
        time.sleep(0.02)
    if status is None and manager.returncode is not None and manager.returncode < 0:
        failure = manager  # stopped from outside: it sent no EPISODE_END
    # Ctrl-C reaches every process of the terminal's group: run_all's own handler has run long
    # before a child handled it and exited.
    error = failure_of(failure, bag_path) if failure is not None and not interrupted else None
    nodes = [n for n in NODES if n in supervisor.children]
    # After a normal end every node has its EPISODE_END; after a failure a node that was still
    # starting may have missed it: they are told with SIGTERM. One still importing on a loaded
    # machine may take longer than the grace to get there: after a failure, its termination is
    # part of ending the run, not a node that missed its end.
    forced = supervisor.stop(nodes, SHUTDOWN_GRACE_S,
                             interrupt=bool(interrupted or failure or status or manager.returncode))
    warn_forced([(name, how) for name, how in forced
                 if how != "terminated" or failure is None])
    status = manager.returncode if status is None else status
    return (128 + interrupted[0], None) if interrupted and error is None else (status, error)


def unfinished_bag(name: str, bag_path: Path | None) -> str:
    """What follows a failed node's line: for the recorder, how to save its bag's complete
    chunks (a recorder that failed left its bag unfinished); '' for the others."""
    return f"; the bag {bag_path} is not finished, its complete chunks: python -m " \
           f"clnn_ros.bag repair {bag_path} [--out DIR]" \
        if name == RECORDER and bag_path is not None else ""


def failure_of(child, bag_path: Path | None = None) -> str:
    """The last lines of a failed child's stderr, at once and together (they came amid the
    others'); returns what the error line says of it (run_all's last line, processes.run_end)."""
    for line in child.last_lines():
        say(f"  {child.name}| {line}")
    return f"{child.describe_exit()}{unfinished_bag(child.name, bag_path)}"


def warn_forced(forced: list[tuple[str, str]]) -> None:
    """One line for each child that Supervisor.stop had to stop."""
    for name, how in forced:
        if how == "terminated":
            say(f"run_all: warning: node {name} did not exit in time; terminated")
        else:
            say(f"run_all: warning: node {name} did not exit in time, nor on SIGTERM (hung in "
                f"native code: seen in Fast DDS's participant deletion, docs/ROS_GRAPH.md); "
                f"killed")


def start_recorder(supervisor: Supervisor, values: dict, bag_path: Path, workdir: Path,
                   namespace: str, environment: str) -> None:
    """The recorder: its own process, also in composed mode; OSError if the bag's directory
    cannot be created. `environment`: what runs as the environment node, kept in the bag."""
    bag_path.mkdir(parents=True, exist_ok=True)
    params_file = write_params(workdir / "recorder_params.yaml", {
        **values, "bag_path": str(bag_path), "environment": environment})
    supervisor.start(RECORDER, [sys.executable, "-m", "clnn_ros.nodes.recorder",
                                *node_arguments(params_file, namespace)], child_environment(),
                     shows_stacks=True)


def stop_recorder(supervisor: Supervisor, episode_ended: bool) -> bool:
    """After the nodes: the recorder ends by itself after EPISODE_END; otherwise (Ctrl-C, the
    trial manager stopped from outside), or when it is stopped (SIGSTOP: the end, sent while it
    could not take it, is gone with its sender), it is told to finish the bag now, which it does
    once continued. Returns whether it had to be terminated."""
    told = not episode_ended or stopped(supervisor.children[RECORDER].process.pid)
    warn_forced(forced := supervisor.stop([RECORDER], RECORDER_GRACE_S, interrupt=told))
    return bool(forced)


def fresh_summary(out: Path, since: float) -> dict:
    """The trial manager's summary.json of this run ({} if it wrote none)."""
    path = out / "summary.json"
    try:
        if path.stat().st_mtime >= since:
            return json.loads(path.read_text())
    except (OSError, ValueError):
        pass
    return {}
