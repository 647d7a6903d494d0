"""Offline analysis of a recorded run, from the bag alone (no ROS graph, no live results).

    python -m clnn_ros.analyze BAG [--out DIR] [--trial N] [--animate N] [--salvage]

BAG: a bag directory (as run_all records it: DIR/metadata.yaml, DIR/DIR_0.mcap) or its .mcap file.
Writes into DIR (default: <bag>_analysis, beside the bag directory or the .mcap file):
    trials.csv           seed,trial,initial_angle_deg,steps,end_reason (as run_all writes it)
    learning_curve.png   successful steps per trial, coloured by how each trial ended
    traces.png           the chosen trial against the tick: cart position and velocity, pole
                         angle and angular velocity, action, reward and punishment
    raster.png           the chosen trial's spikes: an overview of the whole trial and its first
                         and last 200 ticks tick by tick, with the action, reward and punishment
    weights.csv          every /rln/weights snapshot (one per trial end): trial,tick,neuron,segment,input,weight
    final_weights.npy    the last snapshot, shape (neurons, segments, inputs), as run_all saves it
    weights.png          the last snapshot per neuron, on a colour scale from 0 to w_max, and
                         each weight's change since the first snapshot
    weights_history.png  every weight (neuron, segment, input) over the run, from every snapshot
    trial_N.gif          with --animate N: trial N's cart and pole, with each tick's spikes and
                         action (at most 300 frames)
    summary.md           what the bag holds and what the run did (environment, physics,
                         encoding), and what each picture shows
The chosen trial (--trial, default the longest) is read from the messages' header stamps (sim
time), decoded with the schemas embedded in the bag; segments are numbered from 0 and inputs
labelled as the messages do. Exit status: 0 done, 1 the bag cannot be read (missing, not MCAP,
truncated: --salvage reads the complete chunks of a file whose recorder was killed, `python -m
clnn_ros.bag repair` makes a finished copy) or the results cannot be written, 2 a refused
argument (a trial not in the bag, an --out that cannot be a directory). The results are written
together: a refused or failed analysis leaves no file behind.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from .bag import METADATA_FILE, BagError, Decoder, iter_raw, mcap_file, open_bag
from .cli import OneLineArgumentParser
from .core.params import ParamError, Params, params_from_strings
from .files import cannot_create, describe_write_error
from .message_fields import END, EPISODE_END, REACHED_MAX_STEPS, START, TRIALS_CSV_HEADER
from .names import (ACTION, PER_TICK, REWARD, RUN_SETTINGS, SPIKES, STATE, TOPIC_TYPES,
                    TRIAL_EVENT, WEIGHTS, absolute)

# What each picture shows, for summary.md ({trial}: the chosen trial; trial_N.gif: ANIMATION).
PICTURES = {
    "learning_curve.png": "successful steps per trial, coloured by how each trial ended",
    "traces.png": "trial {trial} against the tick: cart position and velocity, pole angle and "
                  "angular velocity, action, reward and punishment, scaled to the motion",
    "raster.png": "trial {trial}'s spikes tick by tick (a long trial's first and last 200 "
                  "ticks, under an overview of the whole trial: the share of ticks each input "
                  "spiked), with the action, rewards and punishments",
    "weights.png": "the last weight snapshot, per neuron: segments (from 0) x the bag's input "
                   "intervals, on a colour scale from 0 to w_max; below, each weight's change "
                   "since the first snapshot",
    "weights_history.png": "every weight over the run, one panel per neuron and segment, one "
                           "line per input, a point per snapshot (trial end)",
}
ANIMATION = "trial {trial}'s cart and pole, with each tick's spikes and action beside them"
REINFORCEMENT = {"reward": 1, "punish": -1}  # Reward.kind; "none" is 0
# The recorder's `environment` (run_all's --env, or its --env-node command): what ran, and
# whose physics. Bags recorded before it was kept have none.
ENVIRONMENTS = {
    "cartpole": ("the built-in cart-pole node (`python -m clnn_ros.nodes.environment`)",
                 "`{physics}` equations, `{integrator}` integration (the built-in node's)"),
    "gymnasium": ("gymnasium's CartPole-v1 node (`python -m clnn_ros.nodes.gymnasium_env`)",
                  "gymnasium's CartPole-v1 (the run's physics parameter does not apply)"),
    "mujoco": ("the MuJoCo cart-pole node (`python -m clnn_ros.nodes.mujoco_env`)",
               "MuJoCo's, with gymnasium CartPole-v1's constants (the run's physics parameter "
               "does not apply)"),
    "external": ("an external node (`run_all --env external`: started outside run_all)",
                 "the external node's own (the graph's parameter physics={physics}, which it "
                 "may ignore)"),
}
OWN_ENVIRONMENT = ("your own node: `{command}` (`run_all --env-node`)",
                   "the node's own (the graph's parameter physics={physics}, which it may "
                   "ignore)")
UNRECORDED_ENVIRONMENT = ("not recorded in this bag (a recorder that run_all did not start, or "
                          "an older recording)",
                          "parameter physics={physics}, integrator={integrator} (which node "
                          "computed it is not recorded)")


class UsageError(Exception):
    """A refused argument (exit status 2), found before anything is written."""


class OutputError(Exception):
    """The results could not be written (exit status 1); none were kept."""


def metadata_record(reader) -> dict:
    """The bag's `clnn_ros` metadata record ({} if it has none readable)."""
    try:
        if isinstance(reader, Path):  # salvaged: the record precedes the first chunk
            from mcap.records import Chunk, Metadata
            from mcap.stream_reader import StreamReader
            with open(reader, "rb") as stream:
                for record in StreamReader(stream).records:
                    if isinstance(record, Chunk):
                        break
                    if isinstance(record, Metadata) and record.name == "clnn_ros":
                        return dict(record.metadata)
        else:
            for record in reader.iter_metadata():
                if record.name == "clnn_ros":
                    return dict(record.metadata)
    except Exception:  # no readable record: the paper's defaults
        pass
    return {}


def run_parameters(record: dict) -> tuple[Params, dict]:
    """The run's parameters from the metadata record (defaults where absent or unreadable) and
    every value it gives."""
    try:
        given = json.loads(record.get("parameters", "{}"))
    except ValueError:
        given = {}
    if not isinstance(given, dict):
        given = {}
    model = {k: v for k, v in given.items() if k not in RUN_SETTINGS}
    try:
        return params_from_strings(model), given
    except ParamError:
        return Params(), given


def read_bag(path: Path, salvage: bool):
    """One pass over the bag: events and weights decoded, ticks of every per-tick topic counted
    from the header stamps (sim time), the raw states, spikes, rewards and actions kept per
    tick."""
    reader, stream = open_bag(path, salvage)
    with stream:
        record = metadata_record(mcap_file(path) if salvage else reader)
        params, given = run_parameters(record)
        tau_ns = round(params.tau * 1e9)
        decode = Decoder()
        events, weights = [], []
        ticks = {topic: [] for topic in PER_TICK}
        raw = {STATE: {}, SPIKES: {}, REWARD: {}, ACTION: {}}
        schemas = {}
        counts = {topic: 0 for topic in TOPIC_TYPES}
        recorded_as = {}  # relative name: the name in the bag (its namespace)
        for schema, topic, sim_ns, _log_ns, data, name in iter_raw(reader):
            recorded_as[topic] = name
            counts[topic] = counts.get(topic, 0) + 1
            if topic == TRIAL_EVENT:
                events.append(decode(schema, data))
            elif topic == WEIGHTS:
                weights.append(decode(schema, data))
            elif topic in ticks:
                tick = sim_ns // tau_ns
                ticks[topic].append(tick)
                if topic in raw:
                    raw[topic][tick] = data
                    schemas[topic] = schema
    return dict(params=params, given=given, record=record, events=events, weights=weights,
                ticks=ticks, raw=raw, schemas=schemas, counts=counts, decode=decode,
                recorded_as=recorded_as)


def trial_rows(events) -> list[list]:
    return [[e.seed, e.trial, float(e.initial_angle_deg), e.successful_steps, e.end_reason]
            for e in events if e.event == END]


def write_trials(rows, path: Path) -> None:
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(TRIALS_CSV_HEADER)
        writer.writerows(rows)


def gaps(ticks: list[int]) -> tuple[int, int, int]:
    """(first tick, last tick, ticks missing in between) of one topic."""
    if not ticks:
        return -1, -1, 0
    unique = np.unique(np.asarray(ticks))
    return int(unique[0]), int(unique[-1]), int(unique[-1] - unique[0] + 1 - len(unique))


def trial_window(events, trial: int) -> tuple[int, int | None]:
    start = next((e.tick for e in events if e.event == START and e.trial == trial), None)
    end = next((e.tick for e in events if e.event == END and e.trial == trial), None)
    return start, end


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


def input_labels(data, inputs: int | None = None) -> list[str]:
    """The encoder's interval labels as the bag's first spike vector carries them; input numbers
    where the bag holds none, or where they are not `inputs` labels."""
    spikes = data["raw"][SPIKES]
    if spikes:
        labels = list(data["decode"](data["schemas"][SPIKES], spikes[min(spikes)]).input_labels)
        if inputs is None or len(labels) == inputs:
            return labels
    return [f"input {i}" for i in range(inputs or data["params"].n_inputs)]


def trial_series(data, trial: int):
    """The ticks of `trial` that have a state in the bag, with their spikes, actions and
    reinforcement (a TrialSeries), or None if the bag holds no state of it."""
    from .analysis_figures import TrialSeries
    raw, decode, schemas = data["raw"], data["decode"], data["schemas"]
    start, end = trial_window(data["events"], trial)
    if start is None:  # an END without its START (the default trial is taken from the ENDs)
        return None
    if end is None:  # the run stopped inside this trial: up to its last state
        end = max(raw[STATE], default=start)
    ticks = [t for t in range(start, end + 1) if t in raw[STATE]]
    if not ticks:
        return None

    def messages(topic):  # per tick; None where the bag has none
        return [decode(schemas[topic], raw[topic][t]) if t in raw[topic] else None
                for t in ticks]

    states = messages(STATE)
    labels = input_labels(data)
    spikes = np.zeros((len(labels), len(ticks)), dtype=np.uint8)
    for k, vector in enumerate(messages(SPIKES)):
        if vector is not None:
            spikes[:, k] = np.frombuffer(bytes(vector.spikes), np.uint8)
    last = states[-1]
    return TrialSeries(
        trial=trial, ticks=np.array(ticks),
        states=np.array([(s.cart_position_m, s.cart_velocity_m_per_s, s.pole_angle_deg,
                          s.pole_angular_velocity_deg_per_s) for s in states]),
        spikes=spikes, input_labels=labels,
        actions=np.array([a.force_direction if a else 0 for a in messages(ACTION)]),
        reinforcement=np.array([REINFORCEMENT.get(r.kind, 0) if r else 0
                                for r in messages(REWARD)]),
        steps=last.successful_steps, end_reason=last.failure_reason or REACHED_MAX_STEPS)


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
    if trial is None and rows:
        trial = max(rows, key=lambda r: (r[3], -r[1]))[1]
    episode_end = next((e for e in events if e.event == EPISODE_END), None)
    seed = rows[0][0] if rows else (events[0].seed if events else data["given"].get("seed"))
    result = dict(data=data, rows=rows, chosen=None, final=None, episode_end=episode_end,
                  seed=seed, produced=[], animated=animate)
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
    from . import analysis_figures as pictures
    data, rows, produced = result["data"], result["rows"], result["produced"]
    params = data["params"]
    write_trials(rows, folder / "trials.csv")
    produced.append("trials.csv")
    if rows:
        pictures.save(pictures.learning_curve_figure(
            rows, params.max_steps,
            f"Learning curve from the bag: seed {result['seed']}, {len(rows)} trials"),
            folder / "learning_curve.png")
        produced.append("learning_curve.png")
    series = trial_series(data, trial) if trial is not None else None
    if series is not None:
        start, end = series.ticks[0], series.ticks[-1]
        result["chosen"] = {"trial": trial, "start": start, "end": end,
                            "ticks": len(series.ticks), "steps": series.steps,
                            "end_reason": series.end_reason}
        pictures.save(pictures.traces_figure(
            series, params.angle_limit_deg, params.track_limit_m,
            f"Trial {trial} from the bag: ticks {start}-{end} ({series.steps:,} successful "
            f"steps, {series.end_reason})"), folder / "traces.png")
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
    pictures.save(pictures.weights_figure(
        final, labels, data["params"].w_max,
        f"Weights after trial {last.trial} (tick {last.tick}), from the bag",
        *((history[0], snapshots[0].trial) if len(snapshots) > 1 else ())),
        folder / "weights.png")
    pictures.save(pictures.weights_history_figure(
        np.array([s.trial for s in snapshots]), history, labels,
        f"Weights over the run: {len(snapshots)} snapshots, one after each trial"),
        folder / "weights_history.png")
    result["produced"] += ["weights.csv", "final_weights.npy", "weights.png",
                           "weights_history.png"]


def environment_lines(data: dict, labels: list[str]) -> list[str]:
    """Markdown list items: the environment node, its physics, the encoding, the velocity
    edge."""
    params = data["params"]
    name = data["record"].get("environment", "")
    node, physics = ENVIRONMENTS.get(name) or (OWN_ENVIRONMENT if name else
                                               UNRECORDED_ENVIRONMENT)
    variables = "pole angle" if params.nsv == 1 else "pole angle and cart velocity"
    edges = ", ".join(f"{e:g}" for e in params.angle_edges_deg)
    velocity = (f"{params.velocity_edge:g} m/s (cart velocity intervals: below -e, [-e, e), e "
                f"and above)" if params.nsv == 2 else
                f"not used: 1 state variable encodes the pole angle only (parameter "
                f"{params.velocity_edge:g} m/s)")
    return [f"* environment: {node.format(command=name)}",
            f"* physics: " + physics.format(physics=params.physics,
                                            integrator=params.integrator),
            f"* encoding: {variables} ({params.nsv} state variable{'s' * (params.nsv > 1)}), "
            f"{len(labels)} inputs: "
            + ", ".join(f"`{label}`" for label in labels) + f" (angle edges {edges} deg)",
            f"* velocity edge: {velocity}"]


def summary_markdown(bag_path: Path, result: dict, salvage: bool) -> str:
    data, rows, chosen = result["data"], result["rows"], result["chosen"]
    steps = [r[3] for r in rows]
    params = data["params"]
    cap = params.max_steps
    end = result["episode_end"]
    inputs = result["final"].shape[2] if result["final"] is not None else params.n_inputs
    lines = [f"# Analysis of `{bag_path.name}`", "",
             "Rebuilt from the bag alone by `python -m clnn_ros.analyze`"
             + (" (salvaged: the file was not finished, only its complete chunks)" if salvage
                else "") + ".", "",
             "## Run", "",
             f"* seed {result['seed']}, step cap {cap:,}",
             *environment_lines(data, input_labels(data, inputs)),
             "* how it ended: " + (f"EPISODE_END, `{end.end_reason}` at tick {end.tick}" if end
                                    else "no EPISODE_END in the bag (interrupted, or the "
                                         "recorder was killed)"),
             f"* trials completed: {len(rows)}" + (
                 f"; mean successful steps {np.mean(steps):.1f}, best {max(steps):,}, last "
                 f"{steps[-1]:,}" if rows else ""),
             ]
    first_cap = next((r[1] for r in rows if r[3] >= cap), None)
    if rows:
        lines.append("* first trial to reach the step cap: "
                     + (f"trial {first_cap}" if first_cap is not None else "none"))
        ends = {}
        for r in rows:
            ends[r[4]] = ends.get(r[4], 0) + 1
        lines.append("* trial ends: " + ", ".join(f"{k} {v}" for k, v in sorted(ends.items())))
    pictures = {name: what.format(trial=chosen and chosen["trial"])
                for name, what in PICTURES.items()}
    if result["animated"] is not None:
        pictures[f"trial_{result['animated']}.gif"] = ANIMATION.format(trial=result["animated"])
    lines += ["", "## Pictures", ""]
    lines += [f"* `{name}`: {what}" for name, what in pictures.items()
              if name in result["produced"]]
    lines += ["", "## Messages", "", "| topic | type | messages | ticks | missing ticks |",
              "|---|---|---:|---|---:|"]
    for topic, type_name in TOPIC_TYPES.items():
        if topic in data["ticks"]:
            first, last, missing = gaps(data["ticks"][topic])
            span = f"{first}-{last}" if first >= 0 else "-"
        else:
            span, missing = "-", "-"
        name = data["recorded_as"].get(topic, absolute(topic))
        lines.append(f"| `{name}` | `{type_name}` | {data['counts'].get(topic, 0):,} | {span} "
                     f"| {missing} |")
    if rows:
        lines += ["", "## Trials", "", "| trial | initial angle (deg) | steps | end |",
                  "|---:|---:|---:|---|"]
        lines += [f"| {r[1]} | {r[2]:g} | {r[3]:,} | {r[4]} |" for r in rows]
    if chosen:
        lines += ["", f"## Trial {chosen['trial']}", "",
                  f"Ticks {chosen['start']}-{chosen['end']} ({chosen['ticks']} states in the "
                  f"bag), {chosen['steps']:,} successful steps, ended by {chosen['end_reason']}.",
                  "", "![traces](traces.png)"]
        if "raster.png" in result["produced"]:
            lines += ["", "![raster](raster.png)"]
    if result["final"] is not None:
        w = result["final"]
        lines += ["", "## Weights", "",
                  f"{w.shape[0]} neurons x {w.shape[1]} segments x {w.shape[2]} inputs, "
                  f"published by the agent after trial {data['weights'][-1].trial} "
                  f"(`weights.csv` has all {len(data['weights'])} snapshots).", "",
                  "![weights](weights.png)", "", "![weights over the run](weights_history.png)"]
    if rows:
        lines += ["", "## Learning curve", "", "![learning curve](learning_curve.png)"]
    return "\n".join(lines) + "\n"


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
    parser = OneLineArgumentParser(prog="python -m clnn_ros.analyze", name="analyze",
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
          f"summary.md to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
