"""What the analysis reads of a bag (clnn_ros.analysis.analyze): the run's parameters from its
metadata record, run_all's notes in metadata.yaml (how far the run went), its task (env/task;
a bag of contract version 3 or before: the paper's cart-pole), its trial events and weight
snapshots, each per-tick topic's ticks (each message's tick) and the raw states, spikes, rewards
and actions, each trial's return, and one trial's series.

A bag of contract version 4 holds Observations on env/observation (values in the task's
variable order) and Actions by index; an older one CartPoleStates on cartpole/state and Actions
by force direction: read as the state of the bag all the same (data["state_type"] says which)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..bag import (Decoder, begins_with_a_stamp, iter_raw, mcap_file, metadata_notes, open_bag,
                  tick_of)
from ..core.params import CARTPOLE, ParamError, Params, params_from_strings
from ..core.task import Action, Task, Variable, cartpole_task
from ..graph.fields import (ACTION_NONE, CARTPOLE_TERMINATIONS, END, REACHED_MAX_STEPS, START,
                            tick_nanoseconds)
from ..graph.names import (ACTION, INPUT_LABELS, OLDER_STATE, PER_TICK, REWARD, SPIKES, STATE,
                          TASK, TOPIC_TYPES, TRIAL_EVENT, WEIGHTS)
from ..graph.run import RUN_SETTINGS
from ..graph.task_description import Described, described
from .series import TrialSeries

REINFORCEMENT = {(1, 0): 1, (0, 1): -1}  # by Reward.reward_one_hot; none (0, 0) is 0
OLDER_STATE_TYPE = "clnn_ros_msgs/msg/CartPoleState"  # the state of contract versions 1 to 3
# The end of a trial that the bag holds but not its last observation's end (the run stopped)
UNFINISHED = "unfinished"


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
    """One pass over the bag: events, weights and the task decoded, ticks of every per-tick
    topic counted (each message's tick; /clock's from its sim time), the raw states, spikes,
    rewards and actions kept per tick. An older bag's cartpole/state is its state (STATE)."""
    reader, stream = open_bag(path, salvage)
    with stream:
        record = metadata_record(mcap_file(path) if salvage else reader)
        params, given = run_parameters(record)
        tau_ns = tick_nanoseconds(params.tau)
        decode = Decoder()
        events, weights, labels, task = [], [], None, None
        ticks = {topic: [] for topic in PER_TICK}
        raw = {STATE: {}, SPIKES: {}, REWARD: {}, ACTION: {}}
        schemas = {}
        counts = {topic: 0 for topic in TOPIC_TYPES}
        recorded_as = {}  # relative name: the name in the bag (its namespace)
        types = {}  # relative name: the type in the bag
        stamped = {}  # schema id: whether its messages begin with a stamp (bag.tick_of)
        for schema, topic, _log_ns, data, name in iter_raw(reader):
            topic = STATE if topic == OLDER_STATE else topic
            recorded_as[topic], types[topic] = name, schema.name
            counts[topic] = counts.get(topic, 0) + 1
            if topic == TASK:
                task = task or decode(schema, data)  # latched: the first is the graph's
            elif topic == TRIAL_EVENT:
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
    data = dict(params=params, given=given, record=record, events=events, weights=weights,
                ticks=ticks, raw=raw, schemas=schemas, counts=counts, decode=decode,
                recorded_as=recorded_as, types=types, labels=labels, notes=metadata_notes(path),
                state_type=types.get(STATE, TOPIC_TYPES[STATE]))
    data["task"] = bag_task(data, task)
    return data


def bag_task(data: dict, msg) -> Described:
    """The bag's task: its env/task (contract version 4); the paper's cart-pole in a bag of
    before (CartPoleStates), or in one whose description cannot be read where the run's task
    is the cart-pole; else a task of the run's name whose variables are numbered."""
    params = data["params"]
    if msg is not None:
        try:
            return described(msg)
        except (ParamError, AttributeError, TypeError, ValueError):
            pass
    if data["state_type"] == OLDER_STATE_TYPE or params.task == CARTPOLE:
        return Described(cartpole_task(params), CARTPOLE_TERMINATIONS)
    states = data["raw"][STATE]
    count = len(data["decode"](data["schemas"][STATE], states[min(states)]).values) \
        if states else params.nsv
    return Described(Task(params.task, tuple(Variable(f"value_{i}") for i in range(count)),
                          tuple(Action(str(k), k) for k in range(params.n_actions)),
                          params.max_steps))


def is_cartpole(data: dict) -> bool:
    """Whether the bag's task is the paper's cart-pole (drawn as such: force directions, the
    cart and the pole)."""
    return data["task"].task.name == CARTPOLE


def state_values(state) -> tuple:
    """A state's values in its task's variable order: an Observation's values, an older bag's
    CartPoleState's four fields (m, m/s, deg, deg/s)."""
    values = getattr(state, "values", None)
    if values is not None and not callable(values):
        return tuple(values)
    return (state.cart_position_m, state.cart_velocity_m_per_s, state.pole_angle_deg,
            state.pole_angular_velocity_deg_per_s)


def end_reason(state, task: Described) -> str:
    """How the trial of its last state ended: an Observation's termination by its task's
    reasons, REACHED_MAX_STEPS where it was truncated, UNFINISHED where neither (the run
    stopped). An older CartPoleState's: the limit it crossed, else REACHED_MAX_STEPS (a bag of
    before 2026-12-04 names the limit in failure_reason; a later one numbers it in failure)."""
    if hasattr(state, "terminated"):
        if state.terminated:
            return task.end_reason(state.termination)
        return REACHED_MAX_STEPS if state.truncated else UNFINISHED
    failure = getattr(state, "failure", None)
    if failure is None:
        return state.failure_reason or REACHED_MAX_STEPS
    return CARTPOLE_TERMINATIONS[failure - 1] if 0 < failure <= len(CARTPOLE_TERMINATIONS) \
        else REACHED_MAX_STEPS


def action_value(action, cartpole: bool):
    """What the pictures draw of an action: the cart-pole's force direction (-1, +1; 0 for
    none), another task's action index (NaN for none). An older bag's Action carries its force
    direction."""
    if action is None or getattr(action, "action", ACTION_NONE) == ACTION_NONE:
        direction = getattr(action, "force_direction", None)
        if direction is not None:
            return direction
        return 0 if cartpole else np.nan
    if cartpole:
        return -1 if action.action == 0 else 1
    return action.action


def trial_returns(data: dict) -> dict[int, float]:
    """Each trial's return: the sum of its observations' rewards (Observation.reward; the first
    of a trial is 0), by the trial they carry. {} for an older bag: its states carry none."""
    raw, schema = data["raw"][STATE], data["schemas"].get(STATE)
    if not raw or data["state_type"] == OLDER_STATE_TYPE:
        return {}
    returns = {}
    for tick in sorted(raw):
        msg = data["decode"](schema, raw[tick])
        returns[msg.trial] = returns.get(msg.trial, 0.0) + float(msg.reward)
    return returns


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
    task, cartpole = data["task"], is_cartpole(data)
    spikes = np.zeros((len(labels), len(ticks)), dtype=np.uint8)
    for k, vector in enumerate(messages(SPIKES)):
        if vector is not None and len(vector.spikes) == len(labels):  # else not the graph's
            spikes[:, k] = np.frombuffer(bytes(vector.spikes), np.uint8)
    last = states[-1]
    values = [state_values(s) for s in states]
    variables = task.task.variables
    if len({len(v) for v in values}) != 1 or len(values[0]) != len(variables):
        variables = tuple(Variable(f"value_{i}") for i in range(max(map(len, values))))
        values = [v + (np.nan,) * (len(variables) - len(v)) for v in values]  # not the task's
    return TrialSeries(
        trial=trial, ticks=np.array(ticks), states=np.array(values, dtype=np.float64),
        spikes=spikes, input_labels=labels,
        actions=np.array([action_value(a, cartpole) for a in messages(ACTION)]),
        reinforcement=np.array([REINFORCEMENT.get(tuple(r.reward_one_hot), 0) if r else 0
                                for r in messages(REWARD)]),
        steps=last.successful_steps, end_reason=end_reason(last, task),
        variables=variables, action_labels=None if cartpole else task.task.action_labels)
