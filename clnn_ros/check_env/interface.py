"""The rules the graph sees of the checked node before the first tick: it starts, announces its
readiness, has the contract's name, topics, types and QoS, runs on sim time and describes its
task, latched; a node of an older contract is named in one line. Each check_* function reads
the graph through the probe and yields what is wrong (docs/ENV_CONTRACT.md)."""

from __future__ import annotations

from typing import Iterator

from rcl_interfaces.msg import ParameterType
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from ..core.params import Params
from ..graph.names import ACTION, CLOCK, READY, STATE, TASK, TRIAL_EVENT, absolute
from ..graph.task_description import Described
from ..session.rclpy_session import resend_until_answered
from .probe import APPEAR_S, REPLY_S, Probe
from .rules import NAME, TYPES, Abort, Findings, check_description, older_contract


def connect(probe: Probe, findings: Findings, run: Params) -> Described:
    """Wait for the node and its endpoints to meet the harness's, then check what the graph
    sees of it; the node's task as described. Abort when the process has exited, when it speaks
    an older contract (findings.older) or describes no task the graph can read."""
    node = probe.node
    # The readiness bound counts from the node's arrival: a loaded machine may take seconds to
    # start its process. A node of an older contract never announces itself in a graph of
    # version 4 (nobody subscribes its cartpole/state): it is known by that publisher.
    probe.spin(max(probe.startup_s, APPEAR_S),
               lambda: probe.environment_present() or NAME in node.ready)
    ready = probe.spin(probe.startup_s,
                       lambda: NAME in node.ready or bool(node.older_state_publishers()))
    findings.checked.update(("starts", "readiness", "interface", "lockstep", "task"))
    if probe.process.poll() is not None:
        findings.fail("starts", f"exited with status {probe.process.returncode} before the "
                                f"first tick{probe.stderr_tail()}")
        raise Abort
    if node.older_state_publishers() and not probe.spin(REPLY_S, lambda: node.tasks):
        findings.older = older_contract(probe.namespace)
        raise Abort
    ready = ready and NAME in node.ready
    # Discovery is one-sided: the node's readers knowing the harness's writers (its readiness)
    # says nothing of the writers knowing the readers; a loaded machine takes seconds for that,
    # so it gets the start-up bound.
    probe.spin(probe.startup_s, lambda: all(p.get_subscription_count()
                                            for p in harness_publishers(probe).values())
               and probe.environment_present() and node.get_publishers_info_by_topic(STATE)
               and node.get_publishers_info_by_topic(TASK))
    if not ready:
        findings.fail_all("readiness", check_readiness(probe))
    for check in (check_node_name, check_subscriptions, check_publishers,
                  check_subscription_qos):
        findings.fail_all("interface", check(probe))
    findings.checked.add("sim_time")
    findings.fail_all("sim_time", check_sim_time(probe))
    return check_task(probe, findings, run)


def check_task(probe: Probe, findings: Findings, run: Params) -> Described:
    """task: the node's TaskDescription, as the graph reads it and against the run; a
    subscription made later gets it too (latched). Abort where there is none to read."""
    node = probe.node
    if not probe.spin(probe.startup_s, lambda: node.tasks):
        findings.fail("task", f"no TaskDescription on {absolute(TASK, probe.namespace)} within "
                              f"{probe.startup_s:g} s (the graph waits for it before the first "
                              f"tick; publish it once, TRANSIENT_LOCAL){probe.exit_status()}"
                              f"{probe.endpoints('publishes')}")
        raise Abort
    task, problems = check_description(node.tasks[0], run)
    findings.fail_all("task", problems)
    if task is None:
        raise Abort
    late = node.late_task()
    if not probe.spin(REPLY_S, lambda: late):
        findings.fail("task", f"not latched: a subscription to {TASK} made after the node "
                              f"published it got nothing within {REPLY_S:g} s (TRANSIENT_LOCAL, "
                              f"its history kept: a recorder or viewer that joins later reads it)")
    return task


def harness_publishers(probe: Probe) -> dict:
    node = probe.node
    return {CLOCK: node.clock_pub, TRIAL_EVENT: node.event_pub, ACTION: node.action_pub}


def check_readiness(probe: Probe) -> Iterator[str]:
    """readiness: (called when no announcement came) what the node announced instead, and
    what it publishes."""
    ready = probe.node.ready
    yield f"no readiness announcement: no String '{NAME}' on " \
          f"{absolute(READY, probe.namespace)} (TRANSIENT_LOCAL) within {probe.startup_s:g} s" \
          + (f"; it announced {sorted(set(ready))}" if ready else "") \
          + probe.endpoints("publishes")


def check_node_name(probe: Probe) -> Iterator[str]:
    """interface: a node named 'environment' in the namespace it was given."""
    if probe.environment_present():
        return
    node = probe.node
    elsewhere = sorted(namespace for name, namespace in node.get_node_names_and_namespaces()
                       if name == NAME)
    yield f"no node named '{NAME}' in namespace {probe.namespace}" + (
        f" (one in {', '.join(elsewhere)}: the node must take its namespace from --ros-args "
        f"-r __ns:=...)" if elsewhere else
        f" (nodes: {sorted(set(node.get_node_names()) - {node.get_name()})})")


def check_subscriptions(probe: Probe) -> Iterator[str]:
    """interface: it subscribes clock, trial/event and rln/action in its namespace, with a QoS
    that matches the graph's publishers."""
    ns = probe.namespace
    for topic, publisher in harness_publishers(probe).items():
        if publisher.get_subscription_count():
            continue
        theirs = [i for i in probe.node.get_subscriptions_info_by_topic(topic)
                  if i.node_name == NAME and i.node_namespace == ns]
        why = f": its subscription's QoS does not match RELIABLE, VOLATILE " \
              f"({theirs[0].qos_profile.reliability.name}, " \
              f"{theirs[0].qos_profile.durability.name})" if theirs else \
              " (topic names must be relative, resolved in the node's namespace)" + \
              probe.endpoints("subscribes")
        yield f"does not subscribe {absolute(topic, ns)} ({TYPES[topic]}){why}"


def check_publishers(probe: Probe) -> Iterator[str]:
    """interface: it publishes env/observation (RELIABLE, VOLATILE) and env/task (RELIABLE,
    TRANSIENT_LOCAL) in its namespace, of the contract's types."""
    for topic, durability in ((STATE, DurabilityPolicy.VOLATILE),
                              (TASK, DurabilityPolicy.TRANSIENT_LOCAL)):
        infos = probe.node.get_publishers_info_by_topic(topic)
        if not infos:
            yield f"does not publish {absolute(topic, probe.namespace)} (topic names must be " \
                  f"relative){probe.endpoints('publishes')}"
        for info in infos:
            if info.topic_type != TYPES[topic]:
                yield f"publishes {topic} as {info.topic_type}, not {TYPES[topic]}"
            if info.qos_profile.reliability != ReliabilityPolicy.RELIABLE:
                yield f"publishes {topic} {info.qos_profile.reliability.name}, not RELIABLE"
            if info.qos_profile.durability != durability:
                yield f"publishes {topic} {info.qos_profile.durability.name}, not " \
                      f"{durability.name}"


def check_subscription_qos(probe: Probe) -> Iterator[str]:
    """interface: its subscriptions have the contract's types, and are RELIABLE."""
    for topic in (CLOCK, TRIAL_EVENT, ACTION):
        for info in probe.node.get_subscriptions_info_by_topic(topic):
            if info.node_name != NAME or info.node_namespace != probe.namespace:
                continue
            if info.topic_type != TYPES[topic]:
                yield f"subscribes {topic} as {info.topic_type}, not {TYPES[topic]}"
            # rclpy's TimeSource adds a BEST_EFFORT subscription to the clock
            elif info.qos_profile.reliability != ReliabilityPolicy.RELIABLE and topic != CLOCK:
                yield f"subscribes {topic} {info.qos_profile.reliability.name}, not RELIABLE"


def check_sim_time(probe: Probe) -> Iterator[str]:
    """sim_time: use_sim_time is true, read through the node's parameter services."""
    client = AsyncParameterClient(probe.node, f"{probe.namespace.rstrip('/')}/{NAME}")
    if not probe.spin(probe.startup_s, client.services_are_ready):
        yield f"cannot read use_sim_time: its parameter services do not answer within " \
              f"{probe.startup_s:g} s"
        return
    future = resend_until_answered(lambda: client.get_parameters(["use_sim_time"]),
                                   lambda future, s: probe.spin(s, future.done),
                                   probe.startup_s, REPLY_S)
    if not future.done() or future.result() is None:
        yield f"cannot read use_sim_time: no answer within {probe.startup_s:g} s"
        return
    values = future.result().values
    if not values or values[0].type != ParameterType.PARAMETER_BOOL or not values[0].bool_value:
        yield "use_sim_time is not true (the node's ROS time must be the graph's sim time)"
