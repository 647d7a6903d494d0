"""What the command-line tools share."""

from __future__ import annotations

import argparse
import signal
import threading
from contextlib import contextmanager


class OneLineArgumentParser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line `<name>: error: <message>` and exit
    status 2 (argparse prints the usage, then the error). name: the tool's name in its other
    error lines, e.g. "run_all"; default: prog (subcommand parsers get theirs from argparse)."""

    def __init__(self, *args, name: str | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.name = name or self.prog

    def error(self, message):
        self.exit(2, f"{self.name}: error: {message}\n")


class Terminated(BaseException):
    """SIGTERM, raised in the main thread: a command ends as on Ctrl-C (its worker processes
    ended, what it stored kept) instead of dying at once and leaving its workers orphaned."""


def raise_terminated(signum, frame) -> None:
    raise Terminated


@contextmanager
def sigterm_raises():
    """Within: SIGTERM raises Terminated in the main thread (called in another, nothing
    changes: only the main thread sets handlers)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
