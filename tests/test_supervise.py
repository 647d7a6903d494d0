"""clnn_ros.processes.supervise: how run_all stops a child that does not end by itself."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from clnn_ros.processes.supervise import Grace, Supervisor, stopped

IGNORES_SIGTERM = ("import signal, sys, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); "
                   "print('ready', file=sys.stderr, flush=True); time.sleep(60)")
SLEEPS = "import sys, time; print('ready', file=sys.stderr, flush=True); time.sleep(60)"


def test_a_child_that_ignores_sigterm_is_killed_and_told_apart_from_a_terminated_one():
    """A process hung in native code with Python's lock held cannot run its SIGTERM handler,
    as one that ignores SIGTERM: it is killed, and said to be, not "terminated"."""
    supervisor = Supervisor()
    try:
        for name, code in (("sleeper", SLEEPS), ("stubborn", IGNORES_SIGTERM)):
            child = supervisor.start(name, [sys.executable, "-c", code], dict(os.environ))
            deadline = time.monotonic() + 60  # a hang bound: it has set its handler
            while "ready" not in child.last_lines() and time.monotonic() < deadline:
                time.sleep(0.05)
        forced = supervisor.stop(["sleeper", "stubborn"], 0.1, interrupt=False)
        assert forced == [("sleeper", "terminated"), ("stubborn", "killed")]
        assert supervisor.children["stubborn"].returncode == -9
        assert supervisor.children["sleeper"].returncode == -15
    finally:
        supervisor.close()


def test_a_node_that_does_not_stop_in_time_shows_where_it_hangs():
    """Before it terminates a node of its own, run_all has it print the stack of every thread
    (process_signals.SHOW_STACKS), so the run's log says where it hung; another child (an
    --env-node command) is not sent that signal, which could end it."""
    hangs = ("import signal, sys, time\n"
             "from clnn_ros.session.process_signals import catch_signals\n"
             "received = catch_signals(); print('ready', file=sys.stderr, flush=True)\n"
             "def stuck_here():  # deaf to the first request, ends on the second\n"
             "    while len(received) < 2: time.sleep(0.01)\nstuck_here()")
    supervisor = Supervisor()
    try:
        for name, shows_stacks in (("ours", True), ("theirs", False)):
            child = supervisor.start(name, [sys.executable, "-c", hangs], dict(os.environ),
                                     shows_stacks=shows_stacks)
            deadline = time.monotonic() + 60  # a hang bound: it has set its handlers
            while "ready" not in child.last_lines() and time.monotonic() < deadline:
                time.sleep(0.05)
        forced = supervisor.stop(["ours", "theirs"], 0.1, interrupt=True)
        assert forced == [("ours", "terminated"), ("theirs", "terminated")]
        assert any("in stuck_here" in line for line in supervisor.children["ours"].last_lines())
        assert not any("stuck_here" in line
                       for line in supervisor.children["theirs"].last_lines())
    finally:
        supervisor.close()


def test_a_child_told_to_stop_while_still_importing_ends_without_a_traceback():
    """A node that has not yet set its signal handlers (still importing its modules on a
    loaded machine) when run_all stops the run after a failure: it is told with SIGTERM, which
    ends it silently, not with SIGINT, which would print a KeyboardInterrupt traceback."""
    importing = "import sys, time; print('ready', file=sys.stderr, flush=True); time.sleep(60)"
    supervisor = Supervisor()
    try:
        child = supervisor.start("starting", [sys.executable, "-c", importing], dict(os.environ))
        deadline = time.monotonic() + 60  # a hang bound
        while "ready" not in child.last_lines() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert supervisor.stop(["starting"], 10.0, interrupt=True) == []  # ended when told
        child.close()
        assert child.returncode == -15 and child.last_lines() == ["ready"]
    finally:
        supervisor.close()


def test_a_childs_grace_does_not_count_the_time_it_waited_for_a_cpu():
    """Slow is not hung: a child that shares one CPU with two busy processes runs a third of
    the time, and its grace (supervise.Grace) counts little of the wall time; a sleeping
    child's counts all of it."""
    busy = "while True: pass"
    one_cpu = min(os.sched_getaffinity(0))
    processes = [subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE)
                 for code in (busy, busy, busy, SLEEPS)]
    try:
        for process in processes[:3]:
            os.sched_setaffinity(process.pid, {one_cpu})
        assert processes[3].stderr.readline() == b"ready\n"  # started: now it only sleeps
        starved, sleeping = Grace(processes[0].pid), Grace(processes[3].pid)
        began = time.monotonic()
        time.sleep(2.0)
        wall = time.monotonic() - began
        assert starved.elapsed() < 0.7 * wall, (starved.elapsed(), wall)
        assert sleeping.elapsed() > 0.9 * wall, (sleeping.elapsed(), wall)
    finally:
        for process in processes:
            process.kill()
            process.wait()


def test_a_childs_grace_does_not_count_the_time_it_was_stopped():
    """A stopped child (SIGSTOP, a debugger) is alive, not hung: a recorder stopped past its
    grace was terminated once continued instead of finishing its bag (issue 37). Its grace
    counts none of the time it is seen stopped, and again runs once it is continued."""
    process = subprocess.Popen([sys.executable, "-c", SLEEPS], stderr=subprocess.PIPE)
    try:
        assert process.stderr.readline() == b"ready\n"
        os.kill(process.pid, signal.SIGSTOP)
        grace = Grace(process.pid)
        for _ in range(10):
            time.sleep(0.1)
            assert grace.elapsed() < 0.05
        assert stopped(process.pid)
        os.kill(process.pid, signal.SIGCONT)
        time.sleep(0.3)
        assert not stopped(process.pid)
        assert grace.elapsed() > 0.25
    finally:
        process.kill()
        process.wait()
