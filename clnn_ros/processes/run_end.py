"""The end of a run_all run, as a user (or a script reading the last line) reads it: the bag's
line first, what the bag lacks and why, and the verdict last (issue 47: an error two or three
lines above `run_all: bag ...` was missed)."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import yaml

from .. import bag
from ..graph.fields import COMPLETED
from ..graph.names import NOT_STARTED, PER_TICK
from ..graph.ticks import (RUN_END_NOTE, RUN_LAST_TICK_NOTE, TICKS_RECORD, TickRanges,
                           describe_ranges)
from .supervise import say


def report_bag(bag_path: Path, status: int | None, summary: dict, recorder_forced: bool,
               recorder_stopped_s: float) -> str:
    """Say where the bag is (or that a graph that gave way removed it, or that nothing was
    recorded) and note in it how far the run went. Returns what the bag lacks of the run's
    ticks and why, in one phrase ('' if nothing): the caller puts it on the last line."""
    if status == NOT_STARTED:
        removed = bag_path.exists()
        bag.remove_bag(bag_path)  # what it holds is another graph's
        print(f"run_all: removed the bag {bag_path}: it held another graph's messages"
              if removed else "run_all: nothing recorded, no bag", flush=True)
        return ""
    with contextlib.suppress(OSError):
        bag_path.rmdir()  # empty: created here to check it could be; nothing was recorded
    finished = (bag_path / bag.METADATA_FILE).is_file()
    if finished or not bag_path.exists():  # an unfinished one: the error line says so
        print(f"run_all: bag {bag_path}" if finished else "run_all: nothing recorded, no bag",
              flush=True)
    if recorder_forced and bag_path.exists() and not finished:  # else its own lines said so
        say(f"run_all: warning: the recorder had to be stopped before it finished the bag: "
            f"python -m clnn_ros.bag repair {bag_path}")
    # The ticks the run completed: an episode ended early leaves its last tick unfinished
    # (a stall's is missing by definition); Ctrl-C's last messages may be in flight.
    done = summary.get("ticks", 0) - (summary.get("exit_reason") != COMPLETED)
    if summary.get("exit_reason") is None or not finished:
        return ""
    note_run(bag_path, summary["exit_reason"], done)
    if summary["exit_reason"] == "interrupted" or done <= 0 or \
            not (lacking := bag_lacks(bag_path, done)):
        return ""
    why = f"; the recorder was stopped (SIGSTOP) for {recorder_stopped_s:.0f} s of the run, and " \
          f"what was sent to it meanwhile did not reach it" if recorder_stopped_s else ""
    return f"the bag lacks {lacking} (the run's ticks: 0-{done - 1}, as in trials.csv{why})"


def note_run(bag_path: Path, exit_reason: str, done: int) -> None:
    """Note in the bag how far the run went: the bag then says so even where the recorder missed
    the episode's end (stopped, or behind when the graph stalled)."""
    try:
        bag.note_in_metadata(bag_path, {RUN_END_NOTE: exit_reason, RUN_LAST_TICK_NOTE: done - 1})
    except (OSError, yaml.YAMLError, KeyError, TypeError) as error:
        say(f"run_all: warning: could not note the run's end in {bag_path / bag.METADATA_FILE}: "
            f"{error}")


def bag_lacks(bag_path: Path, ticks: int) -> str:
    """The ticks of a finished bag's per-tick topics that the run had and the bag lacks, as the
    recorder noted them (graph.ticks), in one phrase; '' if it lacks none."""
    try:
        record = bag.metadata(bag_path, TICKS_RECORD) or {}
    except bag.BagError as error:
        return f"a readable record of its ticks ({error})"
    lacking = []
    for topic in PER_TICK:
        gaps = TickRanges(json.loads(record.get(topic, "[]"))).missing(0, ticks - 1)
        if gaps:
            lacking.append(f"ticks {describe_ranges(gaps)} of {topic}")
    return "; ".join(lacking)
