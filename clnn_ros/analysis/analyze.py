"""Offline analysis of a recorded run, from the bag alone (no ROS graph, no live results).

    python -m clnn_ros.analysis BAG [--out DIR] [--trial N] [--animate N] [--salvage]

BAG: a bag directory (as run_all records it: DIR/metadata.yaml, DIR/DIR_0.mcap) or its .mcap file.
Writes into DIR (default: <bag>_analysis, beside the bag directory or the .mcap file):
    trials.csv           seed,trial,initial_angle_deg,steps,end_reason (as run_all writes it)
    learning_curve.png   successful steps per trial, coloured by how each trial ended (a task
                         other than the cart-pole: and each trial's return)
    traces.png           the chosen trial against the tick: each of the task's variables (the
                         cart-pole: cart position and velocity, pole angle and angular
                         velocity), action, reward and punishment
    raster.png           the chosen trial's spikes: an overview of the whole trial and its first
                         and last 200 ticks tick by tick, with the action, reward and punishment
    weights.csv          every /rln/weights snapshot (one per trial end): trial,tick,neuron,segment,input,weight
    final_weights.npy    the last snapshot, shape (neurons, segments, inputs), as run_all saves it
    weights.png          the last snapshot per neuron, on a colour scale from 0 to w_max, and
                         each weight's change since the first snapshot
    weights_history.png  every weight (neuron, segment, input) over the run, from every snapshot
    trial_N.gif          with --animate N: trial N's cart and pole, with each tick's spikes and
                         action (at most 300 frames; the cart-pole's alone)
    summary.md           what the bag holds and what the run did (task, environment,
                         physics, encoding), the trials (another task's: and their returns),
                         and what each picture shows
The chosen trial (--trial, default the longest) is read from the messages' ticks, decoded
with the schemas embedded in the bag; segments are numbered from 0 and inputs labelled as the
messages do; variables, units and actions as the bag's task (env/task) names them. A bag
recorded before contract version 4 (cartpole/state, Actions by force direction) is read too.
Exit status: 0 done, 1 the bag cannot be read (missing, not MCAP, truncated: --salvage reads
the complete chunks of a file whose recorder was killed, `python -m clnn_ros.bag repair` makes
a finished copy) or the results cannot be written, 2 a refused argument (a trial not in the
bag, an --out that cannot be a directory, --animate of a task other than the cart-pole). The
results are written together: a refused or failed analysis leaves no file behind. What is read
of the bag: analysis.data; summary.md: analysis.summary; the pictures: analysis.figures.
"""

from __future__ import annotations

import contextlib
import csv
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from .data import (input_labels, is_cartpole, read_bag, trial_returns, trial_rows,
                   trial_series)
from .summary import bag_shortfall, summary_markdown
from ..bag import METADATA_FILE, BagError
from ..cli import OneLineArgumentParser
from ..files import cannot_create, describe_write_error
from ..graph.fields import EPISODE_END, REACHED_MAX_STEPS, START, trials_csv
from ..graph.task_description import TERMINATED
from ..graph.names import SPIKES


class UsageError(Exception):
    """A refused argument (exit status 2), found before anything is written."""


class OutputError(Exception):
    """The results could not be written (exit status 1); none were kept."""


def check_trial(events, trial: int, option: str) -> None:
    """UsageError (one line) unless the bag holds the start of `trial`."""
    known = sorted({e.trial for e in events if e.event == START})
    if trial not in known:
        raise UsageError(f"{option}: trial {trial} is not in the bag " + (
            f"(it holds trials {known[0]}..{known[-1]})" if known else "(it holds no trial)"))


def check_output(out: Path) -> None:
    """UsageError (one line) unless `out` is, or can be made, a directory."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"output folder {out} is a file; expected a directory (created if "
                         f"missing)")
    if problem := cannot_create(out):
        raise UsageError(f"output folder {out}: {problem}")


@contextlib.contextmanager
def staged_output(out: Path):
    """A temporary folder for the results, beside or in `out` (the same file system), whose
    files move into `out` once all are written: a failure on the way leaves nothing behind."""
    existing = out.absolute()
    while not existing.exists():
        existing = existing.parent
    staging = Path(tempfile.mkdtemp(prefix=".analysis_", dir=existing))
    try:
        yield staging
        out.mkdir(parents=True, exist_ok=True)
        for path in sorted(staging.iterdir()):
            os.replace(path, out / path.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def analyze(bag_path: Path, out: Path, trial: int | None, salvage: bool,
            animate: int | None = None, progress=None) -> dict:
    """Read the bag, refuse a trial it does not hold (UsageError), then write every result into
    `out` (OutputError if they cannot be written). `progress(frame, frames)`: the GIF's."""
    data = read_bag(bag_path, salvage)
    events = data["events"]
    rows = trial_rows(events)
    for option, number in (("--trial", trial), ("--animate", animate)):
        if number is not None:
            check_trial(events, number, option)
    if animate is not None and not is_cartpole(data):
        raise UsageError(f"--animate draws the cart-pole; the bag's task is "
                         f"{data['task'].task.name} (traces.png shows its variables)")
    if trial is None and rows:
        trial = max(rows, key=lambda r: (r[3], -r[1]))[1]
    episode_end = next((e for e in events if e.event == EPISODE_END), None)
    seed = rows[0][0] if rows else (events[0].seed if events else data["given"].get("seed"))
    result = dict(data=data, rows=rows, chosen=None, final=None, episode_end=episode_end,
                  seed=seed, produced=[], animated=animate,
                  returns={} if is_cartpole(data) else trial_returns(data))
    try:
        with staged_output(out) as folder:
            write_results(result, trial, animate, folder, progress)
            (folder / "summary.md").write_text(summary_markdown(bag_path, result, salvage))
    except OSError as error:
        raise OutputError(describe_write_error(error, out)) from None
    return result


def write_results(result: dict, trial: int | None, animate: int | None, folder: Path,
                  progress) -> None:
    """Every result but summary.md into `folder`; `result` gains what they hold."""
    from . import figures as pictures
    data, rows, produced = result["data"], result["rows"], result["produced"]
    params = data["params"]
    (folder / "trials.csv").write_text(trials_csv(rows))
    produced.append("trials.csv")
    if rows:
        title = f"Learning curve from the bag: seed {result['seed']}, {len(rows)} trials"
        if is_cartpole(data):
            figure = pictures.learning_curve_figure(rows, params.max_steps, title)
        else:
            task = data["task"].task
            figure = pictures.task_learning_curve_figure(
                rows, params.max_steps, f"{task.name}: {title[0].lower()}{title[1:]}",
                end_labels(data["task"]), result["returns"], task.reward_threshold)
        pictures.save(figure, folder / "learning_curve.png")
        produced.append("learning_curve.png")
    series = trial_series(data, trial) if trial is not None else None
    if series is not None:
        start, end = series.ticks[0], series.ticks[-1]
        result["chosen"] = {"trial": trial, "start": start, "end": end,
                            "ticks": len(series.ticks), "steps": series.steps,
                            "end_reason": series.end_reason}
        pictures.save(pictures.traces_figure(
            series, f"Trial {trial} from the bag: ticks {start}-{end} ({series.steps:,} "
                    f"successful steps, {series.end_reason})"), folder / "traces.png")
        produced.append("traces.png")
        if data["raw"][SPIKES]:
            pictures.save(pictures.raster_figure(
                series, f"Spikes of trial {trial} (ticks {start}-{end}), from the bag"),
                folder / "raster.png")
            produced.append("raster.png")
    if data["weights"]:
        write_weights(result, folder, pictures)
    if animate is not None:
        animated = trial_series(data, animate)
        if animated is None:  # raised inside staged_output: what was written goes too
            raise UsageError(f"--animate: trial {animate} has no state in the bag")
        name = f"trial_{animate}.gif"
        pictures.animate_trial(animated, params.pole_length, params.track_limit_m, params.tau,
                               folder / name, progress)
        produced.append(name)


def end_labels(described) -> dict[str, str]:
    """A task's ways to end a trial, in the learning curve's order, with their legends."""
    ending = "failed" if described.task.ends_in == "failure" else "reached"
    return {REACHED_MAX_STEPS: "reached the step cap (truncated)",
            **{r: f"{ending}: {r.replace('_', ' ')}" for r in described.termination_reasons},
            TERMINATED: f"terminated ({described.task.ends_in})"}


def write_weights(result: dict, folder: Path, pictures) -> None:
    """weights.csv, final_weights.npy, weights.png and weights_history.png from the snapshots."""
    data = result["data"]
    snapshots = data["weights"]
    history = np.array([np.asarray(s.weights, dtype=np.float64).reshape(
        s.neurons, s.segments, s.inputs) for s in snapshots])
    with open(folder / "weights.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["trial", "tick", "neuron", "segment", "input", "weight"])
        for snap, weights in zip(snapshots, history):
            for (n, s, i), value in np.ndenumerate(weights):
                writer.writerow([snap.trial, snap.tick, n, s, i, repr(float(value))])
    final = result["final"] = history[-1]
    np.save(folder / "final_weights.npy", final)
    labels = input_labels(data, final.shape[2])
    last = snapshots[-1]
    actions = None if is_cartpole(data) else data["task"].task.action_labels
    if actions is not None and len(actions) != final.shape[0]:  # not the task's network
        actions = tuple(str(k) for k in range(final.shape[0]))
    pictures.save(pictures.weights_figure(
        final, labels, data["params"].w_max,
        f"Weights after trial {last.trial} (tick {last.tick}), from the bag",
        *((history[0], snapshots[0].trial) if len(snapshots) > 1 else (None, None)),
        action_labels=actions), folder / "weights.png")
    pictures.save(pictures.weights_history_figure(
        np.array([s.trial for s in snapshots]), history, labels,
        f"Weights over the run: {len(snapshots)} snapshots, one after each trial",
        action_labels=actions), folder / "weights_history.png")
    result["produced"] += ["weights.csv", "final_weights.npy", "weights.png",
                           "weights_history.png"]


def gif_progress(name: str):
    """A progress line for the GIF, redrawn in place on a terminal; else one line at its start."""
    def show(frame: int, frames: int | None) -> None:
        if sys.stdout.isatty():
            print(f"\ranalyze: {name}: frame {frame + 1}/{frames or '?'}", flush=True,
                  end="\n" if frame + 1 == frames else "")
        elif frame == 0:
            print(f"analyze: writing {name} ({frames or '?'} frames)", flush=True)
    return show


def default_out(bag_path: Path) -> Path:
    """<bag>_analysis beside the bag directory (for DIR/DIR_0.mcap too: beside DIR, never inside
    the bag), or beside a lone .mcap file."""
    base = bag_path
    if bag_path.is_file() and (bag_path.parent / METADATA_FILE).is_file():
        base = bag_path.parent
    elif bag_path.suffix == ".mcap":
        base = bag_path.with_suffix("")
    return base.with_name(base.name + "_analysis")


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.analysis", name="analyze",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", type=Path, help="a bag directory recorded by run_all (or its "
                        ".mcap file)")
    parser.add_argument("--out", type=Path, help="output folder (default: <bag>_analysis)")
    parser.add_argument("--trial", type=int, help="trial to plot (default: the longest)")
    parser.add_argument("--animate", type=int, metavar="N",
                        help="also write trial_N.gif: trial N's cart and pole, spikes and action")
    parser.add_argument("--salvage", action="store_true",
                        help="read an unfinished bag (recorder killed) up to its last complete chunk")
    args = parser.parse_args(argv)
    out = args.out or default_out(args.bag)
    try:
        check_output(out)
        result = analyze(args.bag, out, args.trial, args.salvage, args.animate,
                         gif_progress(f"trial_{args.animate}.gif"))
    except UsageError as error:
        print(f"analyze: error: {error}", file=sys.stderr)
        return 2
    except (BagError, OutputError) as error:
        print(f"analyze: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("analyze: interrupted (nothing written)", file=sys.stderr)
        return 130
    except Exception as error:  # a bag that is MCAP but not a recording of this graph
        print(f"analyze: error: {args.bag}: cannot analyze: {type(error).__name__}: "
              f"{str(error).splitlines()[0] if str(error) else ''}", file=sys.stderr)
        return 1
    rows = result["rows"]
    mean = f", mean steps {np.mean([r[3] for r in rows]):.1f}" if rows else ""
    print(f"analyze: {len(rows)} trials{mean}; wrote {', '.join(result['produced'])} and "
          f"summary.md to {out}", flush=True)
    if short := bag_shortfall(result["data"], result["data"]["notes"], result["episode_end"]):
        print(f"analyze: warning: the bag ends before the run: {short.replace('`', '')}",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
