"""SIGINT, SIGTERM and SIGHUP recorded instead of raised, for every process of the graph and run_all: a
loop then ends between two steps, never inside one (a publish on a context that is shutting down
fails; a half-written file). No ROS import."""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading

# run_all gives each child a pipe on stdin that it never writes to: end of file means run_all
# is gone (even killed with SIGKILL), and the child stops as on SIGTERM.
EXIT_WITH_STDIN = "CLNN_ROS_EXIT_WITH_STDIN"
# What stops a run cleanly, its results kept: Ctrl-C, a kill, a closed terminal.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
# What asks for the Python stack of every thread on stderr: run_all sends it to a node of its own
# that did not stop in time, before it terminates it, so that the run's log says where it hung.
# It is written from the signal handler itself, so a thread blocked in native code is shown too.
SHOW_STACKS = signal.SIGUSR1


def catch_signals() -> list[int]:
    """The signals received so far (a list that grows). With EXIT_WITH_STDIN set, the end of
    stdin counts as SIGTERM. SHOW_STACKS prints the stack of every thread."""
    received = []
    for signum in STOP_SIGNALS:
        signal.signal(signum, lambda number, _frame: received.append(number))
    faulthandler.register(SHOW_STACKS, all_threads=True)
    if os.environ.get(EXIT_WITH_STDIN) == "1":
        def watch_stdin() -> None:
            while os.read(sys.stdin.fileno(), 4096):
                pass
            received.append(signal.SIGTERM)
        threading.Thread(target=watch_stdin, daemon=True, name="stdin-watch").start()
    return received
