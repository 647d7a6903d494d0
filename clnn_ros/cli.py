"""What the command-line tools share."""

from __future__ import annotations

import argparse


class OneLineArgumentParser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line `<name>: error: <message>` and exit
    status 2 (argparse prints the usage, then the error). name: the tool's name in its other
    error lines, e.g. "run_all"; default: prog (subcommand parsers get theirs from argparse)."""

    def __init__(self, *args, name: str | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.name = name or self.prog

    def error(self, message):
        self.exit(2, f"{self.name}: error: {message}\n")
