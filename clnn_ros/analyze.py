"""Offline analysis of a recorded run, from the bag alone (no ROS graph, no live results).

    python -m clnn_ros.analyze BAG [--out DIR] [--trial N] [--salvage]

BAG: a bag directory (as run_all records it: DIR/metadata.yaml, DIR/DIR_0.mcap) or its .mcap file.
Writes into DIR (default: the bag's name without .mcap, plus _analysis):
    trials.csv          seed,trial,initial_angle_deg,steps,end_reason (as run_all writes it)
    learning_curve.png  successful steps per trial
    raster.png          spike raster (inputs x ticks) and actions of the chosen trial
    traces.png          pole angle and cart position of the chosen trial
    weights.csv         every /rln/weights snapshot (one per trial end): trial,tick,neuron,segment,input,weight
    final_weights.npy   the last snapshot, shape (neurons, segments, inputs), as run_all saves it
    weights.png         heat-map of the final weights
    summary.md          what the bag holds and what the run did, for a person to read
The chosen trial (--trial, default the longest) is read from the messages' header stamps (sim
time), decoded with the schemas embedded in the bag. Exit status: 0 done, 1 the bag cannot be
read (missing, not MCAP, truncated: --salvage reads the complete chunks of a file whose recorder
was killed, `python -m clnn_ros.bag repair` makes a finished copy), 2 bad arguments (an unknown
--trial).
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np

from .bag import BagError, Decoder, iter_raw, mcap_file, open_bag
from .cli import OneLineArgumentParser
from .core.params import ParamError, Params, params_from_strings
from .message_fields import (END, END_REASONS, EPISODE_END, REACHED_MAX_STEPS, START,
                             TRIALS_CSV_HEADER)
from .names import (ACTION, PER_TICK, RUN_SETTINGS, SPIKES, STATE, TOPIC_TYPES,
                    TRIAL_EVENT, WEIGHTS, absolute)



class UsageError(Exception):
    pass


def run_parameters(reader) -> tuple[Params, dict]:
    """The run's parameters from the bag's clnn_ros metadata record (defaults if absent)."""
    given = {}
    try:
        if isinstance(reader, Path):  # salvaged: the record precedes the first chunk
            from mcap.records import Chunk, Metadata
            from mcap.stream_reader import StreamReader
            with open(reader, "rb") as stream:
                for record in StreamReader(stream).records:
                    if isinstance(record, Chunk):
                        break
                    if isinstance(record, Metadata) and record.name == "clnn_ros":
                        given = json.loads(record.metadata.get("parameters", "{}"))
        else:
            for record in reader.iter_metadata():
                if record.name == "clnn_ros":
                    given = json.loads(record.metadata.get("parameters", "{}"))
    except Exception:  # no readable parameters: the paper's defaults
        pass
    model = {k: v for k, v in given.items() if k not in RUN_SETTINGS}
    try:
        return params_from_strings(model), given
    except ParamError:
        return Params(), given


def read_bag(path: Path, salvage: bool):
    """One pass over the bag: events and weights decoded, ticks of every per-tick topic counted
    from the header stamps (sim time), the raw states, spikes and actions kept per tick."""
    reader, stream = open_bag(path, salvage)
    with stream:
        params, given = run_parameters(mcap_file(path) if salvage else reader)
        tau_ns = round(params.tau * 1e9)
        decode = Decoder()
        events, weights = [], []
        ticks = {topic: [] for topic in PER_TICK}
        raw = {STATE: {}, SPIKES: {}, ACTION: {}}
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
    return dict(params=params, given=given, events=events, weights=weights, ticks=ticks, raw=raw,
                schemas=schemas, counts=counts, decode=decode, recorded_as=recorded_as)


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


def plot_learning_curve(rows, path: Path, max_steps: int, title: str) -> None:
    from .figures import END_COLORS, _save, plt
    fig, ax = plt.subplots(figsize=(9, 3.8), constrained_layout=True)
    trials = np.array([r[1] for r in rows])
    steps = np.array([r[3] for r in rows])
    codes = {reason: status for status, reason in enumerate(END_REASONS)}
    labels = {0: "reached the step cap", 1: "failed: pole angle", 2: "failed: cart position"}
    colors = np.array([codes.get(r[4], 1) for r in rows])
    ax.plot(trials, steps, color="tab:gray", linewidth=0.8)
    for code, label in labels.items():
        mask = colors == code
        if mask.any():
            ax.scatter(trials[mask], steps[mask], s=18, color=END_COLORS[code], label=label,
                       zorder=3)
    ax.axhline(max_steps, color="black", linestyle="--", linewidth=0.8,
               label=f"step cap {max_steps:,}")
    ax.set_xlabel("trial")
    ax.set_ylabel("successful steps")
    ax.set_ylim(0, max_steps * 1.25)
    ax.set_title(title)
    ax.legend(fontsize=8, loc="upper left", ncol=2)
    _save(fig, path)


def plot_raster(spikes: np.ndarray, labels: list[str], actions: np.ndarray, first_tick: int,
                path: Path, title: str) -> None:
    from .figures import _save, plt
    n = spikes.shape[0]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 1.2 + 0.35 * n + 1.2), sharex=True,
                                      gridspec_kw={"height_ratios": [n, 2]},
                                      constrained_layout=True)
    ticks = first_tick + np.arange(spikes.shape[1])
    for i in range(n):
        on = ticks[spikes[i] > 0]
        top.vlines(on, i - 0.4, i + 0.4, color="black", linewidth=0.6)
    top.set_yticks(range(n), labels, fontsize=7)
    top.set_ylim(-0.6, n - 0.4)
    top.set_ylabel("encoder input")
    bottom.step(ticks, actions, where="post", color="tab:purple", linewidth=0.7)
    bottom.set_yticks([-1, 0, 1], ["-F", "none", "+F"])
    bottom.set_ylabel("action")
    bottom.set_xlabel("tick")
    bottom.set_xlim(ticks[0] - 0.5, ticks[-1] + 0.5)
    fig.suptitle(title)
    _save(fig, path)


def analyze(bag_path: Path, out: Path, trial: int | None, salvage: bool) -> dict:
    from .figures import plot_trace, plot_weights

    data = read_bag(bag_path, salvage)
    params, events, decode = data["params"], data["events"], data["decode"]
    rows = trial_rows(events)
    out.mkdir(parents=True, exist_ok=True)
    write_trials(rows, out / "trials.csv")
    produced = ["trials.csv"]
    episode_end = next((e for e in events if e.event == EPISODE_END), None)
    seed = rows[0][0] if rows else (events[0].seed if events else data["given"].get("seed"))
    if rows:
        plot_learning_curve(rows, out / "learning_curve.png", params.max_steps,
                            f"Learning curve from the bag: seed {seed}, {len(rows)} trials")
        produced.append("learning_curve.png")

    # the chosen trial
    if trial is None and rows:
        trial = max(rows, key=lambda r: (r[3], -r[1]))[1]
    chosen = None
    if trial is not None:
        start, end = trial_window(events, trial)
        if start is None:
            known = sorted({e.trial for e in events if e.event == START})
            raise UsageError(f"trial {trial} is not in the bag (it holds trials "
                             f"{known[0]}..{known[-1]})" if known else
                             f"trial {trial} is not in the bag (it holds no trial)")
        if end is None:  # the run stopped inside this trial: up to its last state
            end = max(data["raw"][STATE], default=start)
        ticks = [t for t in range(start, end + 1) if t in data["raw"][STATE]]
        states = [decode(data["schemas"][STATE], data["raw"][STATE][t]) for t in ticks]
        trace = np.array([(s.cart_position_m, s.cart_velocity_m_per_s, s.pole_angle_deg,
                           s.pole_angular_velocity_deg_per_s) for s in states])
        chosen = {"trial": trial, "start": start, "end": end, "ticks": len(ticks),
                  "steps": states[-1].successful_steps if states else 0,
                  "end_reason": (states[-1].failure_reason or REACHED_MAX_STEPS) if states else ""}
        if len(trace):
            plot_trace(trace, 0, out / "traces.png",
                       f"Trial {trial} from the bag: ticks {start}-{end} "
                       f"({chosen['steps']} successful steps, {chosen['end_reason']})",
                       params.angle_limit_deg, params.track_limit_m)
            produced.append("traces.png")
        spike_ticks = [t for t in ticks if t in data["raw"][SPIKES]]
        if spike_ticks:
            vectors = [decode(data["schemas"][SPIKES], data["raw"][SPIKES][t])
                       for t in spike_ticks]
            spikes = np.array([np.frombuffer(bytes(v.spikes), np.uint8) if
                               isinstance(v.spikes, (bytes, bytearray)) else np.asarray(v.spikes)
                               for v in vectors]).T
            actions = np.array([decode(data["schemas"][ACTION], data["raw"][ACTION][t])
                                .force_direction if t in data["raw"][ACTION] else 0
                                for t in spike_ticks])
            plot_raster(spikes, list(vectors[0].input_labels), actions, spike_ticks[0],
                        out / "raster.png", f"Spike raster of trial {trial} (from the bag)")
            produced.append("raster.png")

    # weights
    final = None
    if data["weights"]:
        with open(out / "weights.csv", "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["trial", "tick", "neuron", "segment", "input", "weight"])
            for snap in data["weights"]:
                w = np.asarray(snap.weights, dtype=np.float64).reshape(
                    snap.neurons, snap.segments, snap.inputs)
                for (n, s, i), value in np.ndenumerate(w):
                    writer.writerow([snap.trial, snap.tick, n, s, i, repr(float(value))])
        last = data["weights"][-1]
        final = np.asarray(last.weights, dtype=np.float64).reshape(last.neurons, last.segments,
                                                                   last.inputs)
        np.save(out / "final_weights.npy", final)
        plot_weights(final, out / "weights.png",
                     f"Weights after trial {last.trial} (tick {last.tick}), from the bag")
        produced += ["weights.csv", "final_weights.npy", "weights.png"]

    result = dict(data=data, rows=rows, chosen=chosen, final=final, episode_end=episode_end,
                  seed=seed, produced=produced)
    (out / "summary.md").write_text(summary_markdown(bag_path, result, salvage))
    return result


def summary_markdown(bag_path: Path, result: dict, salvage: bool) -> str:
    data, rows, chosen = result["data"], result["rows"], result["chosen"]
    steps = [r[3] for r in rows]
    cap = data["params"].max_steps
    end = result["episode_end"]
    lines = [f"# Analysis of `{bag_path.name}`", "",
             "Rebuilt from the bag alone by `python -m clnn_ros.analyze`"
             + (" (salvaged: the file was not finished, only its complete chunks)" if salvage
                else "") + ".", "",
             "## Run", "",
             f"* seed {result['seed']}, {data['params'].nsv} state variable(s), step cap "
             f"{cap:,}, physics {data['params'].physics}",
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
                  "", "![traces](traces.png)", "", "![raster](raster.png)"]
    if result["final"] is not None:
        w = result["final"]
        lines += ["", "## Final weights", "",
                  f"{w.shape[0]} neurons x {w.shape[1]} segments x {w.shape[2]} inputs, "
                  f"published by the agent after trial {data['weights'][-1].trial} "
                  f"(`weights.csv` has all {len(data['weights'])} snapshots).", "",
                  "![weights](weights.png)"]
    if rows:
        lines += ["", "## Learning curve", "", "![learning curve](learning_curve.png)"]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.analyze", name="analyze",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", type=Path, help="a bag directory recorded by run_all (or its "
                        ".mcap file)")
    parser.add_argument("--out", type=Path, help="output folder (default: <bag>_analysis)")
    parser.add_argument("--trial", type=int, help="trial to plot (default: the longest)")
    parser.add_argument("--salvage", action="store_true",
                        help="read an unfinished bag (recorder killed) up to its last complete chunk")
    args = parser.parse_args(argv)
    out = args.out or args.bag.with_name(args.bag.stem + "_analysis")
    try:
        result = analyze(args.bag, out, args.trial, args.salvage)
    except BagError as error:
        print(f"analyze: error: {error}", file=sys.stderr)
        return 1
    except UsageError as error:
        print(f"analyze: error: {error}", file=sys.stderr)
        return 2
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
