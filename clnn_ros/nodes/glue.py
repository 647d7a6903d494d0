"""rclpy glue the graph's nodes share, by composition: their QoS, their parameters declared from
the run's description, the content check of an input, readiness, and main(). The contract itself
(names, rules, the run's parameters) is clnn_ros.graph's."""

from __future__ import annotations

import os
import secrets
import sys
import time
from typing import Callable

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter, get_parameter_value, parameter_value_to_python
from rclpy.task import Future
from std_msgs.msg import String

from ..core.params import ParamError, Params
from ..graph import qos
from ..graph.content import RULES
from ..graph.fields import COMPLETED, EPISODE_END
from ..graph.lockstep import Refusals, episode_end_problem
from ..graph.names import CLAIM, READY, SIM_TIME_NODES, TRIAL_EVENT
from ..graph.run import (DESCRIPTIONS, declared_values, node_parameters, read_params_file,
                         names_list)
from ..graph.watch import claim_order, graph_claim, withdrawal, withdrawn_claim
from ..session.rclpy_session import (qos_profile, ros_session, spin_until_finished,
                                      split_ros_arguments)
from ..session.rosenv import PARTICIPANT_LEASE_S

LOCKSTEP_QOS = qos_profile(qos.LOCKSTEP)
# For a graph that gave way to end its nodes: its run_all kills one that has not ended within
# supervise.TERMINATE_S (5 s) of SIGTERM; more on a loaded machine.
LEAVING_S = 20.0
READY_QOS = qos_profile(qos.READY)
CLAIM_QOS = qos_profile(qos.CLAIM)
PROGRESS_QOS = qos_profile(qos.PROGRESS)
LABELS_QOS = qos_profile(qos.LABELS)
ACK_WAIT_S = 2.0  # a node's last messages reach the recorder before the node exits (or this)
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")  # rclpy applies these


def steady_clock() -> Clock:
    """For timers that must run before and between ticks (a node with use_sim_time's default
    clock stands still until /clock moves)."""
    return Clock(clock_type=ClockType.STEADY_TIME)


def declare_run_parameters(node: Node, role: str, run: dict,
                           own: dict | None = None) -> tuple[Params, dict]:
    """The part of the run's values of the node of this `role` (graph.run.node_parameters:
    validated, a ParamError line otherwise), each declared read-only with its description and
    range; `own`: {name: (default, description)} of a node outside the model (the recorder's).
    A node renamed (-r __node:=NAME, a launch file's name=) is refused with a ParamError line:
    the graph finds its nodes by their names (readiness, the watch of publishers, the stall
    lines), so a renamed one would be waited for and its messages taken for a stranger's."""
    if node.get_name() != role:
        raise ParamError(f"the {role} node was renamed '{node.get_name()}': the graph finds its "
                         f"nodes by name; a second graph runs in a namespace of its own "
                         f"(-r __ns:=/NAME), its nodes keep their names")
    defaults = {name: default for name, (default, _) in (own or {}).items()}
    params, settings = node_parameters(run, role, defaults)
    for name, value in declared_values(params, settings, role).items():
        text = own[name][1] if name in (own or {}) else None
        node.declare_parameter(name, list(value) if isinstance(value, tuple) else value,
                               descriptor(name, text), ignore_override=True)
    return params, settings


def descriptor(name: str, text: str | None = None) -> ParameterDescriptor:
    """Read-only (every parameter is read once, at the start), with its description and range."""
    text, constraint = (text, None) if text else DESCRIPTIONS[name]
    result = ParameterDescriptor(name=name, description=text, read_only=True)
    if constraint and isinstance(constraint[0], str):
        result.additional_constraints = "one of: " + ", ".join(constraint)
    elif constraint and isinstance(constraint[0], int):
        result.integer_range = [IntegerRange(from_value=constraint[0], to_value=constraint[1],
                                             step=1)]
    elif constraint:
        result.floating_point_range = [FloatingPointRange(from_value=constraint[0],
                                                          to_value=constraint[1])]
    return result


def given_parameters(argv: list[str]) -> dict:
    """The parameter values of a node's command line, as rcl applies them: its --params-file
    sections (every node's: the run's description gives all nodes the same values) and -p
    rules, a later one over an earlier; rclpy's own parameters left to rclpy."""
    tokens, values = split_ros_arguments(argv)[0], {}
    for option, value in zip(tokens, tokens[1:]):
        if option == "--params-file":
            values.update(read_params_file(value))
        elif option in ("-p", "--param"):
            name, _, text = value.partition(":=")
            values[name] = parameter_value_to_python(get_parameter_value(text))
    return {name: value for name, value in values.items() if name not in RCLPY_PARAMETERS}


def checked(topic: str, params: Params, refusals: Refusals, callback: Callable):
    """A subscription callback: a message goes to `callback` only if it keeps the topic's
    content rule (graph.content.RULES); otherwise it is refused."""
    rule = RULES[topic]

    def receive(msg) -> None:
        reason = rule(msg, params)
        if reason is None:
            callback(msg)
        else:
            refusals.refuse(topic, msg, reason, kind="content")
    return receive


def ends_with_the_episode(finished: Future, refusals: Refusals,
                          standing: Callable[[], tuple[int, list[str]]],
                          log: Callable[[str], None]) -> Callable:
    """A trial/event callback that finishes the node (exit status 0) on this graph's
    EPISODE_END; one of another tick is refused (graph.lockstep.episode_end_problem).
    `standing()`: (the node's tick, the inputs of it that it holds). An episode ended for any
    reason but "completed" has the node `log` where it stood: a stall names the node whose
    message is missing in the trial manager, and the others' lines show who did get what."""
    def on_event(event) -> None:
        if event.event != EPISODE_END:
            return
        tick, held = standing()
        if problem := episode_end_problem(event.tick, tick):
            refusals.refuse(TRIAL_EVENT, event, problem)
        elif not finished.done():
            if event.end_reason != COMPLETED:
                log(f"the episode ended ({event.end_reason}) with this node at tick {tick}, "
                    f"holding {', '.join(held) or 'none of its inputs'}")
            finished.set_result(0)
    return on_event


def endpoints_matched(extra_nodes: str, outputs: list[tuple[object, int]],
                      inputs: list) -> Callable[[], bool]:
    """Whether each publisher of `outputs` [(publisher, subscribers the graph gives it)] has
    matched those and the extra_nodes' (the recorder), and each input subscription its
    publisher. Discovery is one-sided: a reader drops what a writer sends until it has matched
    the writer too, so a start before both sides matched made the first tick wait on discovery
    (a healthy node named "silent at tick 0" on a loaded machine)."""
    extra = len(names_list(extra_nodes))

    def matched() -> bool:
        return (all(p.get_subscription_count() >= n + extra for p, n in outputs) and
                all(s.get_publisher_count() >= 1 for s in inputs))
    return matched


def publishers_by_topic(node: Node, topics) -> dict[str, list[tuple[str, str]]]:
    """{topic: [(node name, namespace) of each publisher]} as the ROS graph has them now."""
    return {topic: [(info.node_name, info.node_namespace) for info in
                    node.get_publishers_info_by_topic(node.resolve_topic_name(topic))]
            for topic in topics}


class Readiness:
    """Announces the node's name on READY once `is_ready()` (endpoints_matched), then again
    every READY_REPEAT_S until `is_running()`: a trial manager that missed the one announcement
    would wait forever."""

    def __init__(self, node: Node, is_ready: Callable[[], bool], is_running: Callable[[], bool]):
        self.is_ready, self.is_running, self.name = is_ready, is_running, node.get_name()
        self._publisher = node.create_publisher(String, READY, READY_QOS)
        self._announced_at = -qos.READY_REPEAT_S
        self._timer = node.create_timer(0.02, self._poll, clock=steady_clock())

    def cancel(self) -> None:
        """No more announcements."""
        self._timer.cancel()

    def _poll(self) -> None:
        if self.is_running():
            self.cancel()
            return
        now = time.monotonic()
        if now - self._announced_at >= qos.READY_REPEAT_S and self.is_ready():
            self._publisher.publish(String(data=self.name))
            self._announced_at = now


class Pace:
    """Ticks at most `rate_hz` a second of wall time (0: as fast as the graph goes): a tick
    offered between two periods of a steady timer is released at the next one."""

    def __init__(self, node: Node, rate_hz: int, release: Callable[[int, bool], None]):
        self.release, self.rate_hz, self.due = release, rate_hz, None
        if rate_hz:
            node.create_timer(1.0 / rate_hz, self._on_period, clock=steady_clock())

    def offer(self, tick: int, starts_trial: bool) -> None:
        if self.rate_hz:
            self.due = (tick, starts_trial)
        else:
            self.release(tick, starts_trial)

    def _on_period(self) -> None:
        if self.due is not None:
            due, self.due = self.due, None
            self.release(*due)


class GraphClaim:
    """Which of two graphs of the same names in one namespace and domain started first. Each
    trial manager publishes its claim (graph.watch.graph_claim) on CLAIM, kept for one that starts
    later, and reads the others' (all of them: qos.CLAIM): `on_other(started_first)` once per
    other graph. Both order two claims alike, so exactly one of the two gives way however late
    discovery lets them meet (in CI a second graph saw the first one's node names only seconds
    after its own first tick)."""

    def __init__(self, node: Node, on_other: Callable[[bool], None]):
        self.claim = graph_claim(time.time_ns(), secrets.token_hex(8))
        self.on_other, self._others, self._log = on_other, set(), node.get_logger()
        self.met_another = False  # another graph's trial manager was here (contested, or heard)
        self._withdrawn = set()  # other graphs' claims withdrawn: those graphs are over
        self._publisher = node.create_publisher(String, CLAIM, CLAIM_QOS)
        self._publisher.publish(String(data=self.claim))
        self._subscription = node.create_subscription(String, CLAIM, self._receive, CLAIM_QOS)

    def contested(self) -> bool:
        """Whether another graph's trial manager is there: its claim publisher matched (its own
        one aside). A trial manager does not start while one is: on UDP under load the other
        graph's lockstep messages flowed seconds before its claim (and its node names), and a
        graph that started meanwhile ran mixed with it; and of two graphs started together, the
        one that goes on waits until the other has given way (before, it started while the
        other's nodes were still up, counted their endpoints as its own and stalled at tick 0)."""
        others = self._subscription.get_publisher_count() - 1
        live = {claim for claim in self._others if claim_order(claim)} - self._withdrawn
        # withdrawn ones may have left meanwhile: then a claim heard and not withdrawn counts
        contested = others > len(self._withdrawn) or (others > 0 and bool(live))
        self.met_another |= contested
        return contested

    def withdraw(self) -> None:
        """Say on CLAIM that this graph is over. Its participant's goodbye to DDS can be lost:
        its claim publisher then stays matched until its DDS lease ends (180 s), and a graph
        that waits while another is contesting waited that long for one that had given way."""
        self._publisher.publish(String(data=withdrawal(self.claim)))

    def _receive(self, msg: String) -> None:
        if (withdrawn := withdrawn_claim(msg.data)) is not None:
            if withdrawn != self.claim:
                self._withdrawn.add(withdrawn)
            return
        if msg.data == self.claim or msg.data in self._others:
            return
        self._others.add(msg.data)  # heard, whatever it says
        if (other := claim_order(msg.data)) is None:
            self._log.error(f"refused {CLAIM}: {msg.data[:80]!r} is no claim")
            return
        self.met_another = True
        self.on_other(other < claim_order(self.claim))


class SharedNames:
    """Names two nodes carry before the start (graph.watch.named_twice), and what they mean. With
    no other trial manager about, a stray's: borne for stall_timeout_s, then the graph gives way.
    While another graph's trial manager is here, its claim decides (GraphClaim). After one was
    here, most likely its graph's nodes on their way out (beside CPU hogs 5 s and more after it
    gave way, and then both graphs gave way): borne LEAVING_S more, then left behind as a graph's
    leftovers, named in a warning (a node that was killed, or whose goodbye was lost, stays in
    the ROS graph until its DDS lease ends) and no taint while they stay."""

    def __init__(self, node: Node, claim: GraphClaim, stall_timeout_s: float):
        self._log, self._claim, self._stall_timeout_s = node.get_logger(), claim, stall_timeout_s
        self._since = 0.0  # running time with names shared and no other trial manager here
        self.leftovers = set()

    def unexplained(self, twice: list[str]) -> list[str]:
        """The names two nodes carry, but the leftovers (one gone meanwhile is one no more)."""
        self.leftovers &= set(twice)
        return [name for name in twice if name not in self.leftovers]

    def check(self, twice: list[str], contested: bool, running: float) -> tuple[bool, str | None]:
        """(whether the start waits, why this graph gives way or None), at a check before it."""
        twice = self.unexplained(twice)
        self._since = self._since + running if twice and not contested else 0.0
        if not self._claim.met_another and self._since > self._stall_timeout_s:
            return True, f"two nodes named {', '.join(twice)}"
        if self._since > self._stall_timeout_s + LEAVING_S:
            self.leftovers, self._since = set(twice), 0.0
            self._log.warning(f"starting beside {', '.join(twice)} of the graph that gave way, "
                              f"still in the ROS graph after {self._stall_timeout_s + LEAVING_S:g}"
                              f" s: left unannounced (killed, or the goodbye lost), they go at "
                              f"their DDS lease's end (at most {PARTICIPANT_LEASE_S:g} s)")
            return False, None
        return bool(twice or contested), None


def deliver_published(node: Node) -> None:
    """Wait (ACK_WAIT_S at most in all) until every subscriber has acknowledged what the node
    published: what a lagging subscriber (the recorder) has not received yet is lost with the
    process otherwise."""
    deadline = time.monotonic() + ACK_WAIT_S
    for publisher in node.publishers:
        remaining = deadline - time.monotonic()
        if remaining <= 0 or not publisher.wait_for_all_acked(Duration(seconds=remaining)):
            return


def run_node(make_node: Callable[[dict], Node], argv: list[str] | None = None,
             on_interrupt: Callable[[Node], None] | None = None) -> int:
    """Run one node in its own process until its `finished` future is done; returns the exit
    status. `make_node(run)` builds it from the run's values given on the command line; the
    node has `finished` (a Future of its exit status), `failure` (None, or why it failed: a
    full disk) and `refusals` (graph.lockstep.Refusals). Bad parameters: one error line, exit
    2. A failure: one line, exit 1. SIGINT/SIGTERM: `on_interrupt(node)`, then a clean
    shutdown, exit 0."""
    argv = sys.argv if argv is None else argv
    prog = os.path.basename(argv[0])
    unexpected = split_ros_arguments(argv)[1][1:]
    if unexpected:  # rclpy would ignore them: e.g. a --params-file before --ros-args
        print(f"{prog}: error: unexpected arguments {unexpected}: a node takes ROS arguments "
              f"only, after --ros-args", file=sys.stderr)
        return 2
    with ros_session(argv) as signals:
        try:
            node = make_node(given_parameters(argv))
        except ParamError as error:
            print(f"{prog}: error: {error}", file=sys.stderr)
            return 2
        try:
            spin_until_finished([node], node.finished, signals)
            if signals:  # a requested shutdown is no failure (as ROS 2's own nodes)
                if on_interrupt is not None:
                    on_interrupt(node)
                return 0
            if node.failure:
                print(f"{prog}: error: {node.failure}", file=sys.stderr, flush=True)
            return node.finished.result()
        finally:
            close_node(node)


def close_node(node: Node) -> None:
    """Log what the node refused, let its last messages reach their subscribers, destroy it."""
    if summary := node.refusals.summary():
        node.get_logger().warning(summary)
    deliver_published(node)
    node.destroy_node()


def use_sim_time(node: Node, role: str) -> None:
    """The ROS time of the node of this role for the whole run: the graph's sim time (/clock,
    from the trial manager) if the role is one of names.SIM_TIME_NODES (the environment: the
    contract of docs/ENV_CONTRACT.md) or if it was started with -p use_sim_time:=true, its own
    time otherwise. The encoder, reward and agent
    read no ROS time (the tick of their inputs is their time), and the /clock delivery that
    rclpy's TimeSource takes for use_sim_time cost about a sixth of the CPU of a tick
    (docs/benchmark_graph.md). A later change of use_sim_time is refused, as every other
    parameter is (read-only)."""
    if role in SIM_TIME_NODES:
        node.set_parameters([Parameter("use_sim_time", Parameter.Type.BOOL, True)])
    runs_on = ("the graph's sim time" if node.get_parameter("use_sim_time").value
               else "its own time")
    # rclpy declares it without a description; ros2 param describe shows this one
    node.set_descriptor("use_sim_time", ParameterDescriptor(
        name="use_sim_time", type=ParameterType.PARAMETER_BOOL, read_only=True,
        description=f"whether the node's ROS time is the sim time of /clock; read once at "
                    f"start: the node runs on {runs_on}"))
