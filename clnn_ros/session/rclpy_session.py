"""An rclpy session for one process, as the graph's nodes and the live tools (echo, topics,
save_checkpoint, check-env) use it: SIGINT and SIGTERM recorded instead of raised, ROS arguments
that rcl refuses turned into one error line, the executor, and a client's resent request."""

from __future__ import annotations

import inspect
import os
import sys
import time
from contextlib import contextmanager
from typing import Callable, Iterator, NoReturn

from . import rosenv  # loopback DDS discovery by default, before rclpy loads

import rclpy
import rclpy.logging
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future

from ..core.params import ParamError
from ..graph import qos
from ..graph.run import read_params_file
from .process_signals import catch_signals


def qos_profile(description: qos.Qos) -> QoSProfile:
    """The rclpy QoSProfile of a plain description (clnn_ros.graph.qos)."""
    return QoSProfile(depth=description.depth,
                      reliability=ReliabilityPolicy[description.reliability.upper()],
                      durability=DurabilityPolicy[description.durability.upper()],
                      history=HistoryPolicy[description.history.upper()])


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
    parameters) and a ROS_DOMAIN_ID out of range end the process with one line
    `<prog>: error: ...` and exit status 2."""
    prog = os.path.basename(argv[0]) if argv else "rclpy"
    arguments = split_ros_arguments(argv)[0]
    try:
        if problem := rosenv.domain_id_problem():
            raise ParamError(problem)
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


def exit_keeping_participant(node: Node, status: int) -> NoReturn:
    """A live tool's end once its output is out: its subscriptions and clients are deleted (its
    peers unmatch them at once: no publisher waits for its acknowledgements), its DDS
    participant is not (Fast DDS 2.14 can deadlock deleting one while a peer's endpoint goes
    away, with Python's lock held: seen in echo beside CPU hogs; docs/ROS_GRAPH.md), and the
    process exits with `status`. Its peers forget the participant when its lease ends."""
    for subscription in list(node.subscriptions):
        node.destroy_subscription(subscription)
    for client in list(node.clients):
        node.destroy_client(client)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (BrokenPipeError, ValueError):  # `| head`; a stream already closed
            pass
    os._exit(status)


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
