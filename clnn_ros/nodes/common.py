"""What every node of the graph shares: QoS profiles, content rules, readiness, refusals and
main().

The lockstep protocol and the names are in clnn_ros.names, the QoS descriptions in clnn_ros.qos. No message of tick t+1 can exist
before every node has finished tick t, so a node only ever receives messages of its current
tick; anything else is refused with a logged reason (throttled) and the node's state untouched.
"""

from __future__ import annotations

import inspect
import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from typing import Callable, Iterator

from .. import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)

import rclpy
import rclpy.logging
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from std_msgs.msg import String

from clnn_ros_msgs.msg import TrialEvent

from .. import qos
from ..core.params import ParamError
from ..names import ACTION, CLOCK, READY, REWARD, SPIKES, STATE, TRIAL_EVENT, WEIGHTS
from .parameters import declare_parameters, names_list, read_params_file
from .validate import (action_problem, clock_problem, event_problem, reward_problem,
                       spikes_problem, state_problem, weights_problem)

# What every subscriber of a topic refuses, whoever sent it (validate.py).
CONTENT_RULES = {CLOCK: clock_problem, TRIAL_EVENT: event_problem, STATE: state_problem,
                 SPIKES: spikes_problem, REWARD: reward_problem, ACTION: action_problem,
                 WEIGHTS: weights_problem}


def qos_profile(description: qos.Qos) -> QoSProfile:
    """The rclpy QoSProfile of a plain description (clnn_ros.qos)."""
    return QoSProfile(depth=description.depth,
                      reliability=ReliabilityPolicy[description.reliability.upper()],
                      durability=DurabilityPolicy[description.durability.upper()],
                      history=HistoryPolicy[description.history.upper()])


LOCKSTEP_QOS = qos_profile(qos.LOCKSTEP)
PROGRESS_QOS = qos_profile(qos.PROGRESS)
READY_QOS = qos_profile(qos.READY)
# The recorder's progress (the last tick it holds on every per-tick topic): the trial manager
# keeps the graph at most RECORDER_WINDOW ticks ahead of it, far less than the publishers'
# history, so a slow recorder slows the graph down instead of losing messages.
RECORDER_WINDOW = 500
# Seen once in a suite beside CPU hogs: the trial manager never took the recorder's one
# announcement (TRANSIENT_LOCAL, reliable; a reader that joined later got it) and waited for it.
READY_REPEAT_S = 1.0
ACK_WAIT_S = 2.0  # a node's last messages reach the recorder before the node exits (or this)
REFUSAL_LOG_S = 1.0  # at most one refusal line per topic per second (a flood fills no disk)
# run_all gives each child a pipe on stdin that it never writes to: end of file means run_all
# is gone (even killed with SIGKILL), and the node stops as on SIGTERM.
EXIT_WITH_STDIN = "CLNN_ROS_EXIT_WITH_STDIN"


class ReadyAnnouncer:
    """A participant's readiness on READY: announced once `is_ready()`, and again every
    READY_REPEAT_S until `is_running()` (a trial manager that missed the one announcement
    would wait forever)."""

    def __init__(self, node: Node, name: str, is_ready: Callable[[], bool],
                 is_running: Callable[[], bool]):
        self._publisher = node.create_publisher(String, READY, READY_QOS)
        self._name, self._is_ready, self._is_running = name, is_ready, is_running
        self._announced_at = -READY_REPEAT_S
        self.done = False

    def poll(self) -> None:
        """Call often (a steady timer): announces when due."""
        if self.done or self._is_running():
            self.done = True
            return
        now = time.monotonic()
        if now - self._announced_at >= READY_REPEAT_S and self._is_ready():
            self._publisher.publish(String(data=self._name))
            self._announced_at = now


def steady_clock() -> Clock:
    """For timers that must run before and between ticks (a node with use_sim_time's default
    clock stands still until /clock moves)."""
    return Clock(clock_type=ClockType.STEADY_TIME)


def resend_until_answered(send: Callable[[], Future], wait: Callable[[Future, float], object],
                          timeout_s: float, resend_s: float) -> Future:
    """The future of an idempotent service request, sent again every `resend_s` until one send
    is answered or `timeout_s` has passed; `wait(future, seconds)` spins until it is done or the
    seconds pass. Why again: a server drops its response when its response writer has not yet
    matched the client's reader (rmw_fastrtps waits 100 ms for that: rclpy logs "failed to send
    response"), which the client's service_is_ready cannot see."""
    deadline = time.monotonic() + timeout_s
    while True:
        future = send()
        wait(future, min(resend_s, max(0.0, deadline - time.monotonic())))
        if future.done() or time.monotonic() >= deadline:
            return future


class GraphNode(Node):
    """A node of the graph. It reads the shared parameters into a validated core Params,
    announces on READY once each of its publishers has matched the subscribers the graph gives
    it and each of its subscriptions has matched its publisher (again every READY_REPEAT_S until
    the graph runs), and stops when the trial manager announces the end of the episode."""

    listens_to_trial_events = True  # every node but their publisher, the trial manager
    driven_by_clock = True  # its time is the graph's sim time (use_sim_time)

    def __init__(self, name: str, publishers: dict, context=None, overrides: dict | None = None,
                 namespace: str | None = None, cli_args: list[str] | None = None):
        """publishers: {attribute: (message type, topic, subscribers the graph gives it)};
        overrides: parameter values given in-process (composed mode) instead of --ros-args."""
        super().__init__(name, context=context, namespace=namespace, cli_args=cli_args,
                         automatically_declare_parameters_from_overrides=True,
                         parameter_overrides=[Parameter(k, value=v)
                                              for k, v in (overrides or {}).items()])
        self.params, self.settings = declare_parameters(self)
        if self.driven_by_clock:
            self.set_parameters([Parameter("use_sim_time", Parameter.Type.BOOL, True)])
        self.tau_ns = round(self.params.tau * 1e9)
        self.extra_nodes = names_list(self.settings["extra_nodes"])
        self.failure = None  # why the node failed (fail)
        self.refusals = {}  # (topic, "content" or "tick"): count
        self._unlogged = {}  # topic: [refusals not logged yet, when the last line was logged]
        self.finished = Future()
        self._expected = []
        self._inputs = []  # the subscriptions of subscribe(): each has a publisher in the graph
        for attribute, (msg_type, topic, subscribers) in publishers.items():
            self.add_publisher(attribute, msg_type, topic, subscribers)
        self._ready = ReadyAnnouncer(self, self.get_name(), self.matched,
                                     lambda: self.current_tick() > 0)
        self._ready_timer = self.create_timer(0.02, self._announce_when_matched,
                                              clock=steady_clock())
        if self.listens_to_trial_events:
            self.subscribe(TrialEvent, TRIAL_EVENT, self.on_trial_event)

    def add_publisher(self, attribute: str, msg_type, topic: str, subscribers: int) -> None:
        """A publisher of the graph as self.<attribute>, waited for (readiness, the last
        messages' delivery) like those given to __init__; before the node spins."""
        publisher = self.create_publisher(msg_type, topic, LOCKSTEP_QOS)
        setattr(self, attribute, publisher)
        self._expected.append((publisher, subscribers + len(self.extra_nodes)))

    def matched(self) -> bool:
        """Has each publisher matched the subscribers the graph gives it, and each input its
        publisher? Discovery is one-sided: a writer can match a reader that does not know the
        writer yet; that reader drops what it is sent until it matches the writer too, and only
        then has it sent again (Fast DDS's reliable repair). A start before both sides matched
        made the first tick wait on discovery, which the stall watchdog counted (a healthy
        node named "silent at tick 0" on a loaded machine)."""
        return (all(p.get_subscription_count() >= n for p, n in self._expected) and
                all(s.get_publisher_count() >= 1 for s in self._inputs))

    def _announce_when_matched(self) -> None:
        """Ready once every endpoint has matched, until the graph runs (ReadyAnnouncer)."""
        self._ready.poll()
        if self._ready.done:
            self._ready_timer.cancel()

    def subscribe(self, msg_type, topic: str, callback: Callable) -> None:
        """Subscribe to an input of the graph. A message goes to `callback` only if it keeps the
        topic's content rules (CONTENT_RULES); otherwise it is refused."""
        content_problem = CONTENT_RULES[topic]

        def receive(msg) -> None:
            reason = content_problem(msg, self.params)
            if reason is None:
                callback(msg)
            else:
                self.refuse(topic, msg, reason, kind="content")
        self._inputs.append(self.create_subscription(msg_type, topic, receive, LOCKSTEP_QOS))

    def refuse(self, topic: str, msg, reason: str, kind: str = "tick") -> None:
        """Drop a bad message (the node's state is not touched), count it by kind ("content":
        its content rule; "tick": its tick or its place in the protocol) and log it: the first
        refusal on a topic at once, then at most one line per REFUSAL_LOG_S with the count."""
        self.refusals[topic, kind] = self.refusals.get((topic, kind), 0) + 1
        now = time.monotonic()
        unlogged, logged_at = self._unlogged.get(topic, (0, -REFUSAL_LOG_S))
        if now - logged_at < REFUSAL_LOG_S:
            self._unlogged[topic] = (unlogged + 1, logged_at)
            return
        more = f" (and {unlogged} more since the last line)" if unlogged else ""
        self.get_logger().error(f"refused {topic} tick {getattr(msg, 'tick', '?')}: "
                                f"{reason}{more}")
        self._unlogged[topic] = (0, now)

    def refusal_summary(self) -> str:
        """'refused N messages: topic (kind) count, ...' or ''."""
        if not self.refusals:
            return ""
        parts = ", ".join(f"{topic} ({kind}) {count}"
                          for (topic, kind), count in sorted(self.refusals.items()))
        return f"refused {sum(self.refusals.values())} messages: {parts}"

    def destroy_node(self) -> None:
        if summary := self.refusal_summary():
            self.get_logger().warning(summary)
        self._deliver_published()
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

    def stamp(self, msg, tick: int, trial: int):
        """Fill the common fields: header stamped with the tick's sim time, tick and trial."""
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(tick * self.tau_ns, 1_000_000_000)
        msg.tick, msg.trial = tick, trial
        return msg

    def current_tick(self) -> int:
        """The tick whose inputs the node waits for: its TickJoin's (the environment's own)."""
        return self.join.tick

    def on_trial_event(self, event: TrialEvent) -> None:
        """EPISODE_END(e) ends the node. The trial manager sends it with e the tick it waits
        for (it holds all of tick e-1) or the tick it just completed (the episode's last), and
        no clock follows it: the node has finished tick e-1 and cannot finish tick e+1, so its
        current tick is e or e+1. Any other tick is refused (a stale or forged end, another
        graph's). START and END change nothing here (the environment checks START)."""
        if event.event == TrialEvent.EPISODE_END:
            tick = self.current_tick()
            if event.tick not in (tick - 1, tick):
                self.refuse(TRIAL_EVENT, event, f"EPISODE_END expected at tick {tick - 1} or "
                                                f"{tick}")
            else:
                self.finish(0)

    def interrupted(self) -> None:
        """Called once after Ctrl-C or SIGTERM, before the node is destroyed."""

    def finish(self, exit_code: int) -> None:
        if not self.finished.done():
            self.finished.set_result(exit_code)

    def fail(self, reason: str) -> None:
        """Stop the node with exit status 1 and one line `<prog>: error: <reason>` (a file it
        cannot write); its process ends, and run_all names it."""
        self.failure = reason
        self.get_logger().error(reason)
        self.finish(1)


def make_executor(context=None):
    """rclpy's EventsExecutor, the fastest executor measured here (docs/ROS_GRAPH.md,
    docs/benchmark_graph.md); CLNN_ROS_EXECUTOR=single selects SingleThreadedExecutor instead
    (for comparison), CLNN_ROS_EXECUTOR=events (the default) the EventsExecutor."""
    choice = os.environ.get("CLNN_ROS_EXECUTOR", "events").strip().lower() or "events"
    if choice == "single":
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor(context=context)
    if choice != "events":
        raise ParamError(f"CLNN_ROS_EXECUTOR must be 'single' or 'events', got {choice!r}")
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)


class WithMessageInfo:
    """A subscription callback `function(message, message_info)` under either executor: rclpy
    passes the message info to a callback of two parameters, its SingleThreadedExecutor as two
    arguments, but rclpy 7.1's EventsExecutor as one (message, info) tuple, measured here (a
    plain two-parameter function then fails with SystemError)."""

    __signature__ = inspect.Signature([inspect.Parameter(name, inspect.Parameter.POSITIONAL_ONLY)
                                       for name in ("message", "message_info")])

    def __init__(self, function: Callable[[object, dict], None]):
        self.function = function

    def __call__(self, *arguments) -> None:
        message, info = arguments if len(arguments) == 2 else arguments[0]
        self.function(message, info)


def catch_signals() -> list[int]:
    """Record SIGINT and SIGTERM instead of raising: the spin loop then ends between two
    callbacks, never inside one (a publish on a context that is shutting down fails). With
    EXIT_WITH_STDIN set, the end of stdin counts as SIGTERM."""
    received = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda number, _frame: received.append(number))
    if os.environ.get(EXIT_WITH_STDIN) == "1":
        def watch_stdin() -> None:
            while os.read(sys.stdin.fileno(), 4096):
                pass
            received.append(signal.SIGTERM)
        threading.Thread(target=watch_stdin, daemon=True, name="stdin-watch").start()
    return received


@contextmanager
def ros_session(argv: list[str] | None = None) -> Iterator[list[int]]:
    """rclpy for one process: SIGINT and SIGTERM are recorded (catch_signals) instead of being
    handled by rclpy, and rclpy is shut down on the way out. Yields the signals received."""
    signals = catch_signals()
    init_ros(sys.argv if argv is None else argv)
    try:
        yield signals
    finally:
        rclpy.try_shutdown()


ROS_ARGS_USAGE = "expected --ros-args [-p name:=value] [--params-file FILE] [--log-level LEVEL]"


def init_ros(argv: list[str]) -> None:
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
    except Exception as error:  # rclpy's UnknownROSArgsError and RCLError are not public
        if type(error).__name__ == "UnknownROSArgsError":
            message = f"unknown ROS arguments {error}; {ROS_ARGS_USAGE}"
        else:  # rcl: "failed to initialize rcl: <what>, at <source file>:<line>, ..."
            reason = " ".join(str(error).removeprefix("failed to initialize rcl: ")
                              .split(", at /")[0].split())
            message = f"{reason}; {ROS_ARGS_USAGE}" if reason.startswith("Couldn't parse") \
                else reason
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
    Bad parameters: one error line, exit 2. A node that failed (GraphNode.fail: a full disk):
    one line, exit 1. SIGINT/SIGTERM: clean shutdown, 130/143."""
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
            if node.failure:
                print(f"{prog}: error: {node.failure}", file=sys.stderr, flush=True)
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

    def offer(self, topic: str, msg) -> bool:
        """Take `msg` into this tick's inbox; False (refused) if it does not belong there."""
        if msg.tick != self.tick:
            self.node.refuse(topic, msg, f"expected tick {self.tick}")
            return False
        if topic in self.inbox:
            self.node.refuse(topic, msg, f"a second message for tick {self.tick}")
            return False
        self.inbox[topic] = msg
        if len(self.inbox) == len(self.topics):
            inbox, self.inbox = self.inbox, {}
            self.tick += 1
            self.complete(inbox)
        return True
