"""What the analysis reads of a bag (clnn_ros.analysis.analyze): the run's parameters from its
metadata
record, run_all's notes in metadata.yaml (how far the run went), its trial events and weight
snapshots, each per-tick topic's ticks (each message's tick) and the raw states, spikes, rewards
and actions, and one trial's series."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..bag import (Decoder, begins_with_a_stamp, iter_raw, mcap_file, metadata_notes, open_bag,
                  tick_of)
from ..core.params import ParamError, Params, params_from_strings
from ..graph.fields import END, FAILURE_REASONS, REACHED_MAX_STEPS, START, tick_nanoseconds
from ..graph.names import (ACTION, INPUT_LABELS, PER_TICK, REWARD, SPIKES, STATE, TOPIC_TYPES,
                          TRIAL_EVENT, WEIGHTS)
from ..graph.run import RUN_SETTINGS

REINFORCEMENT = {(1, 0): 1, (0, 1): -1}  # by Reward.reward_one_hot; none (0, 0) is 0


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
    (each message's tick; /clock's from its sim time), the raw states, spikes, rewards and
    actions kept per tick."""
    reader, stream = open_bag(path, salvage)
    with stream:
        record = metadata_record(mcap_file(path) if salvage else reader)
        params, given = run_parameters(record)
        tau_ns = tick_nanoseconds(params.tau)
        decode = Decoder()
        events, weights, labels = [], [], None
        ticks = {topic: [] for topic in PER_TICK}
        raw = {STATE: {}, SPIKES: {}, REWARD: {}, ACTION: {}}
        schemas = {}
        counts = {topic: 0 for topic in TOPIC_TYPES}
        recorded_as = {}  # relative name: the name in the bag (its namespace)
        stamped = {}  # schema id: whether its messages begin with a stamp (bag.tick_of)
        for schema, topic, _log_ns, data, name in iter_raw(reader):
            recorded_as[topic] = name
            counts[topic] = counts.get(topic, 0) + 1
            if topic == TRIAL_EVENT:
                events.append(decode(schema, data))
            elif topic == WEIGHTS:
                weights.append(decode(schema, data))
            elif topic == INPUT_LABELS:
                labels = list(decode(schema, data).labels)
            elif topic in ticks:
                if schema.id not in stamped:
                    stamped[schema.id] = begins_with_a_stamp(schema)
                tick = tick_of(data, tau_ns, stamped[schema.id])
                ticks[topic].append(tick)
                if topic in raw:  # the first of a tick: a second one is a stale or forged copy
                    raw[topic].setdefault(tick, data)
                    schemas[topic] = schema
    return dict(params=params, given=given, record=record, events=events, weights=weights,
                ticks=ticks, raw=raw, schemas=schemas, counts=counts, decode=decode,
                recorded_as=recorded_as, labels=labels, notes=metadata_notes(path))


def end_reason(state) -> str:
    """How the trial of its last state ended: the limit it crossed, else REACHED_MAX_STEPS. (A bag
    of before 2026-12-04 names the limit in failure_reason; one of now numbers it in failure.)"""
    failure = getattr(state, "failure", None)
    if failure is None:
        return state.failure_reason or REACHED_MAX_STEPS
    return FAILURE_REASONS[failure] if 0 < failure < len(FAILURE_REASONS) else REACHED_MAX_STEPS


def trial_rows(events) -> list[list]:
    return [[e.seed, e.trial, float(e.initial_angle_deg), e.successful_steps, e.end_reason]
            for e in events if e.event == END]


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


def input_labels(data, inputs: int | None = None) -> list[str]:
    """The encoder's interval labels as the bag holds them: on rln/input_labels, or in a bag of
    an earlier version in each spike vector; input numbers where the bag holds none, or where
    they are not `inputs` labels."""
    labels, spikes = data["labels"], data["raw"][SPIKES]
    if labels is None and spikes:
        first = data["decode"](data["schemas"][SPIKES], spikes[min(spikes)])
        labels = list(getattr(first, "input_labels", None) or []) or None
    if labels is not None and (inputs is None or len(labels) == inputs):
        return labels
    return [f"input {i}" for i in range(inputs or data["params"].n_inputs)]


def trial_series(data, trial: int):
    """The ticks of `trial` that have a state in the bag, with their spikes, actions and
    reinforcement (a TrialSeries), or None if the bag holds no state of it."""
    from .figures import TrialSeries
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
        if vector is not None and len(vector.spikes) == len(labels):  # else not the graph's
            spikes[:, k] = np.frombuffer(bytes(vector.spikes), np.uint8)
    last = states[-1]
    return TrialSeries(
        trial=trial, ticks=np.array(ticks),
        states=np.array([(s.cart_position_m, s.cart_velocity_m_per_s, s.pole_angle_deg,
                          s.pole_angular_velocity_deg_per_s) for s in states]),
        spikes=spikes, input_labels=labels,
        actions=np.array([a.force_direction if a else 0 for a in messages(ACTION)]),
        reinforcement=np.array([REINFORCEMENT.get(tuple(r.reward_one_hot), 0) if r else 0
                                for r in messages(REWARD)]),
        steps=last.successful_steps, end_reason=end_reason(last))
