"""What every node of the graph shares: topics, QoS, parameters, readiness, and main().

Lockstep protocol (one tick = one physics step tau of sim time; every message carries the tick):

    trial_manager --/clock(t) [+ /trial/event START(t)]--> environment
    environment   --/cartpole/state(t)--> encoder, reward, trial_manager
    encoder       --/rln/spikes(t)--> agent            reward --/rln/reward(t)--> agent
    agent         --/rln/action(t)--> environment (applied at tick t+1), trial_manager
    trial_manager, holding state(t) and action(t), publishes /clock(t+1)

No message of tick t+1 can exist before every node has finished tick t, so a node only ever
receives messages of its current tick; anything else is refused with a logged reason.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from .. import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)

import rclpy
import rclpy.logging
import yaml
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from std_msgs.msg import Empty, String

from clnn_ros_msgs.msg import TrialEvent

from ..core.params import ParamError, Params, params_from_strings
from .publisher_gid import InputsWithGid
from .validate import (action_problem, clock_problem, event_problem, reward_problem,
                       spikes_problem, state_problem, weights_problem)

# Topics of the graph (docs/ENV_CONTRACT.md names them for environment nodes).
CLOCK = "/clock"
TRIAL_EVENT = "/trial/event"
STATE = "/cartpole/state"
SPIKES = "/rln/spikes"
REWARD = "/rln/reward"
ACTION = "/rln/action"
WEIGHTS = "/rln/weights"
READY = "/graph/ready"
# The node whose messages each input topic carries; a node accepts them from no one else.
PUBLISHED_BY = {CLOCK: "trial_manager", TRIAL_EVENT: "trial_manager", STATE: "environment",
                SPIKES: "encoder", REWARD: "reward", ACTION: "agent", WEIGHTS: "agent"}
# Before a topic's publisher is pinned, how long a message's sender may take to appear by name
# in the ROS graph (discovery under load); afterwards an unknown sender is refused at once.
NEW_PUBLISHER_WAIT_S = 2.0
# What every subscriber of a topic refuses, whoever sent it (validate.py).
CONTENT_RULES = {CLOCK: clock_problem, TRIAL_EVENT: event_problem, STATE: state_problem,
                 SPIKES: spikes_problem, REWARD: reward_problem, ACTION: action_problem,
                 WEIGHTS: weights_problem}

# In lockstep a publisher is never more than a few messages ahead of any node of the graph (at
# most END, EPISODE_END and START on /trial/event within one tick). A subscriber outside the
# lockstep (echo, the recorder) may lag: the publisher's history keeps the last 2000 messages
# for it (about 1 s of the graph); the recorder also holds the graph back (RECORDER_WINDOW).
LOCKSTEP_QOS = QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE,
                          history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
# Heartbeats: each node (and the recorder) publishes on ALIVE + its name every HEARTBEAT_S, from
# its executor, so the trial manager tells a dead process (no heartbeat for ALIVE_TIMEOUT_S) from
# a slow one (docs/ROS_GRAPH.md). Not DDS liveliness: a finite lease starts Fast DDS 2.14's
# liveliness protocol, which deadlocked a trial manager here when a participant was killed.
ALIVE = "/graph/alive/"
ALIVE_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
HEARTBEAT_S = 0.1
ALIVE_TIMEOUT_S = 1.0
# The recorder's progress (the last tick it holds on every per-tick topic): the trial manager
# keeps the graph at most RECORDER_WINDOW ticks ahead of it, far less than the publishers'
# history, so a slow recorder slows the graph down instead of losing messages.
RECORDED = "/recorder/progress"
RECORDER_WINDOW = 500
ACK_WAIT_S = 2.0  # a node's last messages reach the recorder before the node exits (or this)
PROGRESS_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
# A readiness announcement must reach a trial manager that starts later than the node; the
# depth keeps every node's announcement when several arrive at once.
READY_QOS = QoSProfile(depth=16, reliability=ReliabilityPolicy.RELIABLE,
                       history=HistoryPolicy.KEEP_LAST,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)

# The nodes the trial manager waits for before the first tick.
GRAPH_NODES = ("environment", "encoder", "reward", "agent")
# Parameters rclpy itself handles.
ROS_BUILTIN_PARAMETERS = {"use_sim_time", "start_type_description_service"}
# Settings of the run that are not model parameters, with their defaults.
RUN_SETTINGS = {"seed": 0, "stall_timeout_s": 5.0, "out_dir": "", "progress": True,
                "extra_nodes": "", "init_weights": ""}
# init_weights: "" the seed's weights; fig7, fig12 or a weights .npy: a new episode with those
# weights; a checkpoint .npz: resume its episode (core.episode.start_from_setting).
# extra_nodes: comma-separated names of participants that subscribe to every topic and announce
# on /graph/ready (the recorder): each publisher waits for them too, and so does the first tick.


class GraphNode(Node):
    """A node of the graph. It reads the shared parameters into a validated core Params,
    announces on /graph/ready once each of its publishers has matched the subscribers the graph
    gives it, and stops when the trial manager announces the end of the episode."""

    listens_to_trial_events = True  # every node but their publisher, the trial manager

    def __init__(self, name: str, publishers: dict, context=None, overrides: dict | None = None):
        """publishers: {attribute: (message type, topic, subscribers the graph gives it)};
        overrides: parameter values given in-process (composed mode) instead of --ros-args."""
        super().__init__(name, context=context,
                         automatically_declare_parameters_from_overrides=True,
                         parameter_overrides=[Parameter(k, value=v)
                                              for k, v in (overrides or {}).items()])
        self.params, self.settings = read_parameters(self)
        self.tau_ns = round(self.params.tau * 1e9)
        self.extra_nodes = {n.strip() for n in self.settings["extra_nodes"].split(",") if n.strip()}
        self.refused = 0
        self._pinned = {}  # input topic: GIDs of the publishers its messages are accepted from
        self._inputs = InputsWithGid(self)  # the input topics' subscriptions
        self.finished = Future()
        self._expected = []
        for attribute, (msg_type, topic, subscribers) in publishers.items():
            publisher = self.create_publisher(msg_type, topic, LOCKSTEP_QOS)
            setattr(self, attribute, publisher)
            self._expected.append((publisher, subscribers + len(self.extra_nodes)))
        self._ready_publisher = self.create_publisher(String, READY, READY_QOS)
        self._alive = Alive(self, name)
        self._ready_timer = self.create_timer(0.02, self._announce_when_matched)
        if self.listens_to_trial_events:
            self.subscribe(TrialEvent, TRIAL_EVENT, self.on_trial_event)

    def publishers_matched(self) -> bool:
        """Has each publisher matched the subscribers the graph gives it?"""
        return all(p.get_subscription_count() >= n for p, n in self._expected)

    def _announce_when_matched(self) -> None:
        if self.publishers_matched() and self.inputs_visible():
            self._ready_publisher.publish(String(data=self.get_name()))
            self._ready_timer.cancel()

    def subscribe(self, msg_type, topic: str, callback: Callable) -> None:
        """Subscribe to an input of the graph. A message goes to `callback` only if it keeps the
        topic's content rules (CONTENT_RULES) and comes from the publisher the graph gives the
        topic (PUBLISHED_BY); otherwise it is refused, for the first reason found."""
        content_problem, pinned = CONTENT_RULES[topic], self._pinned.setdefault(topic, set())

        def receive(msg_and_sender: tuple) -> None:
            msg, publisher_gid = msg_and_sender
            reason = content_problem(msg, self.params)
            if reason is None and publisher_gid not in pinned:
                reason = self._publisher_refusal(topic, publisher_gid)
            if reason is None:
                callback(msg)
            else:
                self.refuse(topic, msg, reason)
        self._inputs.subscribe(msg_type, topic, receive, LOCKSTEP_QOS)

    def destroy_node(self) -> None:
        self._deliver_published()
        self._inputs.close()  # before the node's timers (the doorbell) go
        super().destroy_node()

    def _deliver_published(self) -> None:
        """Wait (ACK_WAIT_S at most in all) until every subscriber has acknowledged what the
        graph's publishers sent: what a lagging subscriber (the recorder) has not received yet
        is lost with the process otherwise."""
        deadline = time.monotonic() + ACK_WAIT_S
        for publisher, _ in self._expected:
            remaining = deadline - time.monotonic()
            if remaining <= 0 or not publisher.wait_for_all_acked(Duration(seconds=remaining)):
                return

    def inputs_visible(self) -> bool:
        """Does the ROS graph show the publisher (PUBLISHED_BY) of each input topic yet? Then
        its first message is known to come from it."""
        return all(PUBLISHED_BY[topic] in self._publishers_of(topic).values()
                   for topic in self._pinned)

    def _publishers_of(self, topic: str) -> dict[bytes, str]:
        """{GID: node name} of the topic's publishers in the ROS graph now (our namespace)."""
        return {bytes(info.endpoint_gid): info.node_name
                for info in self.get_publishers_info_by_topic(topic)
                if info.node_namespace == self.get_namespace()}

    def _publisher_refusal(self, topic: str, publisher_gid: bytes) -> str | None:
        """Why a message from a publisher not pinned is refused; None after pinning it. The
        first publisher of the expected node name to send a message on the topic is pinned, no
        other after it (a publisher of that name that left without a word, like a killed run's
        that the graph still lists for a while, is never pinned). Until then, a sender the ROS
        graph does not name yet gets up to NEW_PUBLISHER_WAIT_S to appear (its node's name
        travels apart from its first message)."""
        pinned, expected = self._pinned[topic], PUBLISHED_BY[topic]
        name = self._publishers_of(topic).get(publisher_gid)
        deadline = time.monotonic() + NEW_PUBLISHER_WAIT_S
        while name is None and not pinned and time.monotonic() < deadline:
            time.sleep(0.01)  # DDS discovery updates the graph on its own threads
            name = self._publishers_of(topic).get(publisher_gid)
        if name == expected and not pinned:
            pinned.add(publisher_gid)
            return None
        sender = f"node '{name}'" if name else "not in the ROS graph"
        return f"from an unknown publisher ({sender}; {topic} is accepted from '{expected}' only)"

    def stamp(self, msg, tick: int, trial: int):
        """Fill the common fields: header stamped with the tick's sim time, tick and trial."""
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(tick * self.tau_ns, 1_000_000_000)
        msg.tick, msg.trial = tick, trial
        return msg

    def refuse(self, topic: str, msg, reason: str) -> None:
        """Log and drop a bad message; the node's state is not touched."""
        self.refused += 1
        self.get_logger().error(f"refused {topic} tick {getattr(msg, 'tick', '?')}: {reason}")

    def on_trial_event(self, event: TrialEvent) -> None:
        if event.event == TrialEvent.EPISODE_END:
            self.finish(0)

    def interrupted(self) -> None:
        """Called once after Ctrl-C or SIGTERM, before the node is destroyed."""

    def finish(self, exit_code: int) -> None:
        if not self.finished.done():
            self.finished.set_result(exit_code)


class Alive:
    """A node's heartbeat: an empty message on ALIVE + its name every HEARTBEAT_S."""

    def __init__(self, node: Node, name: str):
        self.publisher = node.create_publisher(Empty, ALIVE + name, ALIVE_QOS)
        self.message = Empty()
        self.timer = node.create_timer(HEARTBEAT_S, self.beat)

    def beat(self) -> None:
        self.publisher.publish(self.message)


def read_parameters(node: Node) -> tuple[Params, dict]:
    """Every parameter given to the node (command line or --params-file), validated: model
    parameters become a core Params, the rest the run settings; an unknown name is an error.
    Undeclared parameters are then declared with their defaults, so all of them are listed."""
    given = {name: p.value for name, p in node._parameter_overrides.items()
             if name not in ROS_BUILTIN_PARAMETERS}
    settings = dict(RUN_SETTINGS)
    for name in set(given) & set(settings):
        settings[name] = convert_setting(name, given.pop(name))
    if given.get("segments") == 0:
        given.pop("segments")  # 0 stands for the paper's default (ROS has no null parameter)
    params = params_from_strings(given)
    for name, value in {**params.to_dict(), **settings}.items():
        if not node.has_parameter(name):
            node.declare_parameter(name, 0 if value is None else value)
    return params, settings


def read_params_file(path) -> dict:
    """The parameters of a ROS 2 parameters YAML (`<node>: {ros__parameters: {...}}`, every
    node's section merged), or one ParamError line: rcl itself takes some bad files silently
    (a file without any `ros__parameters` section) and refuses others with a traceback. The
    graph's nodes share their parameters, so two sections must not give a name two values."""
    try:
        document = yaml.safe_load(Path(path).read_text())
    except (OSError, UnicodeDecodeError) as error:
        raise ParamError(f"cannot read params file {path}: {error}") from None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        raise ParamError(f"params file {path} is not valid YAML: "
                         f"{getattr(error, 'problem', None) or error}{where}") from None
    sections = {node: v.get("ros__parameters") for node, v in document.items()
                if isinstance(v, dict)} if isinstance(document, dict) else {}
    if not sections or not all(isinstance(s, dict) for s in sections.values()):
        raise ParamError(f"params file {path} must map node names to 'ros__parameters:' "
                         f"mappings, e.g. '/**: {{ros__parameters: {{sigma: 256}}}}'")
    merged, given_by = {}, {}
    for node, section in sections.items():
        for name, value in section.items():
            if name in merged and merged[name] != value:
                raise ParamError(f"params file {path} gives {name} two values ({merged[name]!r} "
                                 f"for {given_by[name]}, {value!r} for {node}); the graph's "
                                 f"nodes share their parameters")
            merged[name], given_by[name] = value, node
    return merged


def convert_setting(name: str, value):
    """A run setting (RUN_SETTINGS) from the command line, a ROS parameter or YAML, checked:
    its default's type (text of a number counts as the number), else one ParamError line."""
    default = RUN_SETTINGS[name]
    if isinstance(default, (bool, str)):
        if type(value) is not type(default):
            expected = "true or false" if isinstance(default, bool) else "text"
            raise ParamError(f"{name} must be {expected}, got {value!r}")
        return value
    if isinstance(value, str):
        try:
            value = int(value, 10) if isinstance(default, int) else float(value)
        except ValueError:
            pass  # refused below with the text itself
    if isinstance(default, int):  # the seed: TrialEvent.seed is a uint32
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**32:
            raise ParamError(f"{name} must be an integer from 0 to 2**32-1, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not 0 < value < float("inf"):
        raise ParamError(f"{name} must be a finite number > 0, got {value!r}")
    return float(value)


def make_executor(context=None):
    """rclpy's EventsExecutor, the fastest executor measured here (docs/ROS_GRAPH.md,
    docs/benchmark_graph.md); CLNN_ROS_EXECUTOR=single selects SingleThreadedExecutor instead
    (for comparison), CLNN_ROS_EXECUTOR=events (the default) the EventsExecutor."""
    choice = os.environ.get("CLNN_ROS_EXECUTOR", "events").strip().lower() or "events"
    if choice == "single":
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor(context=context)
    if choice != "events":
        raise ValueError(f"CLNN_ROS_EXECUTOR must be 'single' or 'events', got {choice!r}")
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)


def catch_signals() -> list[int]:
    """Record SIGINT and SIGTERM instead of raising: the spin loop then ends between two
    callbacks, never inside one (a publish on a context that is shutting down fails)."""
    received = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda number, _frame: received.append(number))
    return received


@contextmanager
def ros_session(argv: list[str] | None = None) -> Iterator[list[int]]:
    """rclpy for one process: SIGINT and SIGTERM are recorded (catch_signals) instead of being
    handled by rclpy, and rclpy is shut down on the way out. Yields the signals received."""
    signals = catch_signals()
    init_rclpy(sys.argv if argv is None else argv)
    try:
        yield signals
    finally:
        rclpy.try_shutdown()


ROS_ARGS_USAGE = "expected --ros-args [-p name:=value] [--params-file FILE] [--log-level LEVEL]"


def init_rclpy(argv: list[str]) -> None:
    """rclpy.init with SIGINT/SIGTERM left to catch_signals. ROS arguments that rcl refuses (a
    bad -p rule, an unknown argument, a params file it cannot parse or that holds no
    parameters) end the process with one line `<prog>: error: ...` and exit status 2."""
    prog = os.path.basename(argv[0]) if argv else "rclpy"
    arguments = split_ros_arguments(argv)[0]
    try:
        for option, value in zip(arguments, arguments[1:]):
            if option == "--params-file":
                read_params_file(value)
        previous = rclpy.logging.get_logger_level("rcl")
        rclpy.logging.set_logger_level("rcl", rclpy.logging.LoggingSeverity.FATAL)  # silent refusal
        try:
            rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
        finally:
            if rclpy.logging.get_logger_level("rcl") == rclpy.logging.LoggingSeverity.FATAL:
                rclpy.logging.set_logger_level("rcl", previous)  # unless --log-level set it
    except ParamError as error:
        message = str(error)
    except _rclpy.UnknownROSArgsError as error:
        message = f"unknown ROS arguments {error}; {ROS_ARGS_USAGE}"
    except _rclpy.RCLError as error:
        # rcl: "failed to initialize rcl: <what>, at <source file>:<line>, ..."
        reason = " ".join(str(error).removeprefix("failed to initialize rcl: ")
                          .split(", at /")[0].split())
        message = f"{reason}; {ROS_ARGS_USAGE}" if reason.startswith("Couldn't parse") else reason
    else:
        return
    print(f"{prog}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def split_ros_arguments(argv: list[str]) -> tuple[list[str], list[str]]:
    """(the tokens rcl reads: those between --ros-args and the next -- or the end, the others)."""
    ros, others, inside = [], [], False
    for token in argv:
        if token in ("--ros-args", "--"):
            inside = token == "--ros-args"
        else:
            (ros if inside else others).append(token)
    return ros, others


def spin_until_finished(nodes: list[Node], finished: Future, signals: list[int]) -> None:
    """Spin `nodes` on one executor (make_executor) until `finished` is done or a signal
    arrived. (EventsExecutor's own spin_until_future_complete does not return when a callback
    completes the future.)"""
    executor = make_executor()
    for node in nodes:
        executor.add_node(node)
    while not finished.done() and not signals:
        executor.spin_once(timeout_sec=0.1)


def node_main(factory: Callable[[], GraphNode], argv: list[str] | None = None) -> int:
    """Run one node in its own process until the episode ends; returns the exit status.
    Bad parameters: one error line, exit 2. SIGINT/SIGTERM: clean shutdown, 130/143."""
    argv = sys.argv if argv is None else argv
    prog = os.path.basename(argv[0])
    unexpected = split_ros_arguments(argv)[1][1:]
    if unexpected:  # rclpy would ignore them: e.g. a --params-file before --ros-args
        print(f"{prog}: error: unexpected arguments {unexpected}: a node takes ROS arguments "
              f"only, after --ros-args", file=sys.stderr)
        return 2
    with ros_session(argv) as signals:
        try:
            node = factory()
        except ParamError as error:
            print(f"{prog}: error: {error}", file=sys.stderr)
            return 2
        try:
            spin_until_finished([node], node.finished, signals)
            if signals:
                node.interrupted()
                return 128 + signals[0]
            return node.finished.result()
        finally:
            node.destroy_node()


class TickJoin:
    """The messages of the current tick, one from each input topic. When all are in, they go to
    `complete` together and the join moves to the next tick; a message of another tick, or a
    second one from the same topic, is refused."""

    def __init__(self, node: GraphNode, topics: tuple[str, ...], complete: Callable[[dict], None]):
        self.node, self.topics, self.complete = node, topics, complete
        self.tick = 0
        self.inbox = {}

    def offer(self, topic: str, msg) -> None:
        if msg.tick != self.tick:
            self.node.refuse(topic, msg, f"expected tick {self.tick}")
        elif topic in self.inbox:
            self.node.refuse(topic, msg, f"a second message for tick {self.tick}")
        else:
            self.inbox[topic] = msg
            if len(self.inbox) == len(self.topics):
                inbox, self.inbox = self.inbox, {}
                self.tick += 1
                self.complete(inbox)
