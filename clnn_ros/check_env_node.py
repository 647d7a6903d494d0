"""Check that an environment node keeps the contract of docs/ENV_CONTRACT.md.

    python -m clnn_ros.check_env_node python -m clnn_ros.nodes.environment --ros-args -p physics:=paper
    python -m clnn_ros.check_env_node python -m clnn_ros.nodes.gymnasium_env
    python -m clnn_ros.check_env_node python examples/noisy_cartpole.py

It starts the command in its own process as run_all would (with `--ros-args --params-file
<file> -r __ns:=/NS -r /clock:=/NS/clock` appended, the file setting max_steps; a pipe on stdin
and CLNN_ROS_EXIT_WITH_STDIN=1), in a private ROS_DOMAIN_ID on loopback and in a namespace of its
own (default /check_env_node: a node that uses absolute topic names fails), and plays trial
manager and agent against it: a balancing trial up to the max_steps cap, a trial pushed with
constant +F until it fails, malformed inputs in between, then EPISODE_END; then it starts the
command once more and closes its stdin. For each rule of the contract it prints PASS or FAIL
with what the node did wrong. Exit status 0 when all pass, 1 otherwise, 2 on a usage error.
Only public rclpy.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from . import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)

import rclpy
from rcl_interfaces.msg import ParameterType
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from clnn_ros_msgs.msg import Action, CartPoleState, TrialEvent

from .cli import OneLineArgumentParser
from .names import ACTION, CLOCK, READY, STATE, TOPIC_TYPES, TRIAL_EVENT, absolute
from .nodes.common import EXIT_WITH_STDIN, LOCKSTEP_QOS, READY_QOS, resend_until_answered

RULES = {
    "starts": "the command starts a node that keeps running",
    "readiness": f"announces 'environment' on {READY} (TRANSIENT_LOCAL) once {STATE} has 3 "
                 f"subscribers",
    "interface": f"node 'environment' in the namespace it is given; subscribes {CLOCK}, "
                 f"{TRIAL_EVENT}, {ACTION}; publishes {STATE} (relative names, clnn_ros_msgs "
                 f"types, RELIABLE, VOLATILE)",
    "sim_time": "use_sim_time is true",
    "lockstep": "state(t) once, only after clock(t) and START(t) or action(t-1); tick t, the "
                "trial, stamp t*tau",
    "reset": "START resets: cart at 0 and at rest, pole at rest at initial_angle_deg, "
             "successful_steps 0, the START's trial",
    "successful_steps": "+1 per successful step, not for the failing one; a trial at max_steps "
                        "ends with force 0 and the next START is accepted",
    "failure": "failed/failure_reason: 'pole_angle' beyond angle_limit_deg, 'cart_position' "
               "beyond track_limit_m, else not failed and ''",
    "refusals": "refuses force_direction not in -1,0,1, an action or clock of another tick, "
                "START mid-trial, START outside the angle limit",
    "episode_end": "exits with status 0 on EPISODE_END",
    "stdin_eof": f"with {EXIT_WITH_STDIN}=1, exits when its stdin reaches end of file",
}
MAX_STEPS = 60  # the cap the checked node gets; the failing trial must fail before it
ANGLE_LIMIT_DEG, TRACK_LIMIT_M, TAU = 12.0, 2.4, 0.02  # the defaults the node gets
TYPES = {topic: TOPIC_TYPES[topic] for topic in (STATE, CLOCK, TRIAL_EVENT, ACTION)}
QUIET_S = 0.3  # how long "no state may come" is watched
REPLY_S = 5.0  # how long a state may take
# How long the node gets to exit (EPISODE_END, end of stdin): its own exit waits up to 2 s for
# its last messages' acknowledgements, then deletes its participant; beside CPU hogs a good node
# took more than 5 s.
EXIT_S = 15.0
APPEAR_S = 20.0  # at least this long for the node to appear in the graph (at start, again)
NAME = "environment"


class Abort(Exception):
    """The node stopped answering: the remaining rules cannot be checked."""


class Harness(Node):
    """Trial manager + agent, in the checked node's namespace: publishes clock, trial/event and
    rln/action, reads the states (the graph does not check who sends a message)."""

    def __init__(self, context, namespace: str):
        super().__init__("check_env_node", context=context, namespace=namespace)
        self.clock_pub = self.create_publisher(Clock, CLOCK, LOCKSTEP_QOS)
        self.event_pub = self.create_publisher(TrialEvent, TRIAL_EVENT, LOCKSTEP_QOS)
        self.action_pub = self.create_publisher(Action, ACTION, LOCKSTEP_QOS)
        self.states: list[CartPoleState] = []
        self.ready: list[str] = []
        # three subscriptions: the encoder, reward and trial manager a real graph has
        self.create_subscription(CartPoleState, STATE, self.states.append, LOCKSTEP_QOS)
        for _ in range(2):
            self.create_subscription(CartPoleState, STATE, lambda _msg: None, LOCKSTEP_QOS)
        self.create_subscription(String, READY, lambda m: self.ready.append(m.data), READY_QOS)

    @staticmethod
    def stamp(msg, tick: int, trial: int):
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(tick * round(TAU * 1e9), 10**9)
        msg.tick, msg.trial = tick, trial
        return msg

    def clock(self, tick: int) -> None:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(tick * round(TAU * 1e9), 10**9)
        self.clock_pub.publish(msg)

    def event(self, kind: int, tick: int, trial: int, angle: float = 0.0) -> None:
        self.event_pub.publish(self.stamp(TrialEvent(event=kind, initial_angle_deg=angle),
                                          tick, trial))

    def action(self, tick: int, trial: int, direction: int) -> None:
        self.action_pub.publish(self.stamp(Action(force_direction=direction,
                                                  force_n=10.0 * direction), tick, trial))


class Checker:
    def __init__(self, command: list[str], domain_id: int, startup_s: float, namespace: str):
        self.command, self.domain_id, self.startup_s = command, domain_id, startup_s
        self.namespace = namespace
        self.problems = {rule: [] for rule in RULES}
        self.checked = set()
        self.more = {}  # rule: problems found beyond the first 3
        self.tick = 0  # the tick whose state comes next
        self.trial = 0
        self.steps = 0  # successful steps of the current trial, as the harness counts them
        self.last = None  # the last state

    # -- bookkeeping -------------------------------------------------------------------------
    def fail(self, rule: str, text: str) -> None:
        """Record a problem; after 3 for a rule, only count them."""
        if text in self.problems[rule]:
            return
        if len(self.problems[rule]) < 3:
            self.problems[rule].append(text)
        else:
            self.more[rule] = self.more.get(rule, 0) + 1

    def spin(self, seconds: float, until=lambda: False) -> bool:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            if until():
                return True
            self.executor.spin_once(timeout_sec=0.01)
            if self.process.poll() is not None:
                return until()
        return until()

    def quiet(self, rule: str, what: str) -> bool:
        """No state may come now; True when none came."""
        seen = len(self.node.states)
        if self.spin(QUIET_S, lambda: len(self.node.states) > seen):
            self.fail(rule, f"{what} (published state tick {self.node.states[seen].tick})")
            self.take_extra(seen)
            return False
        return True

    def take_extra(self, seen: int) -> None:
        """A state that came when it should not: the node has advanced; follow it."""
        msg = self.node.states[seen]
        self.tick = msg.tick + 1
        self.last = msg
        self.steps = msg.successful_steps
        if msg.trial != self.trial:
            self.trial = msg.trial

    def await_state(self, after: str) -> CartPoleState:
        seen = len(self.node.states)
        if not self.spin(REPLY_S, lambda: len(self.node.states) > seen):
            status = self.process.poll()
            why = f" (the process exited with status {status}{self.stderr_tail()})" \
                if status is not None else ""
            self.fail("lockstep", f"publishes no {STATE} after {after}{why}")
            raise Abort
        msg = self.node.states[seen]
        if msg.tick != self.tick:
            self.fail("lockstep", f"state tick {msg.tick} after {after}")
        if msg.trial != self.trial:
            self.fail("lockstep", f"state of tick {self.tick} has trial {msg.trial}, not "
                                  f"{self.trial} (the trial of the last START)")
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        if msg.tick == self.tick and stamp != self.tick * round(TAU * 1e9):
            self.fail("lockstep", f"state of tick {self.tick} is stamped {stamp / 1e9:.9f} s, "
                                  f"not tick * tau = {self.tick * TAU:.9f} s")
        values = (msg.cart_position_m, msg.cart_velocity_m_per_s, msg.pole_angle_deg,
                  msg.pole_angular_velocity_deg_per_s)
        if not all(math.isfinite(v) for v in values):
            self.fail("failure", f"state of tick {self.tick} is not finite: {values}")
        self.check_failure(msg)
        self.last = msg
        self.tick += 1
        return msg

    def check_failure(self, msg: CartPoleState) -> None:
        angle, x = abs(msg.pole_angle_deg), abs(msg.cart_position_m)
        reasons = {"pole_angle": angle > ANGLE_LIMIT_DEG, "cart_position": x > TRACK_LIMIT_M}
        if msg.failed:
            if msg.failure_reason not in reasons:
                self.fail("failure", f"failure_reason {msg.failure_reason!r} is not "
                                     f"'pole_angle' or 'cart_position'")
            elif not reasons[msg.failure_reason]:
                self.fail("failure", f"failure_reason {msg.failure_reason!r} but the state is "
                                     f"inside that limit (angle {msg.pole_angle_deg:.3f} deg, "
                                     f"x {msg.cart_position_m:.3f} m)")
        else:
            if msg.failure_reason:
                self.fail("failure", f"failure_reason {msg.failure_reason!r} on a state that "
                                     f"is not failed")
            if any(reasons.values()):
                self.fail("failure", f"state beyond a limit not reported as failed (angle "
                                     f"{msg.pole_angle_deg:.3f} deg, x {msg.cart_position_m:.3f} m)")

    # -- the scenario ------------------------------------------------------------------------
    def start(self, angle: float, order: str = "start first") -> CartPoleState:
        """START(t) and clock(t) (order: "start first", "clock first", or "start only" when
        clock(t) is out already): a new trial; checks the reset."""
        self.trial += 0 if self.tick == 0 else 1
        if order == "start first":
            self.node.event(TrialEvent.START, self.tick, self.trial, angle)
            self.quiet("lockstep", f"publishes state {self.tick} on START({self.tick}) "
                                   f"without clock({self.tick})")
            self.node.clock(self.tick)
        else:
            if order == "clock first":
                self.node.clock(self.tick)
            self.node.event(TrialEvent.START, self.tick, self.trial, angle)
        previous = self.steps
        msg = self.await_state(f"START({self.tick}) and clock({self.tick})")
        self.checked.add("reset")
        if msg.successful_steps != 0:
            self.fail("reset", f"successful_steps not reset at START (was {previous}, "
                               f"published {msg.successful_steps})")
        if msg.cart_position_m != 0.0 or msg.cart_velocity_m_per_s != 0.0:
            self.fail("reset", f"cart not at 0 and at rest after START (x "
                               f"{msg.cart_position_m:g} m, dx/dt {msg.cart_velocity_m_per_s:g})")
        if abs(msg.pole_angle_deg - angle) > 1e-9 or msg.pole_angular_velocity_deg_per_s != 0.0:
            self.fail("reset", f"pole not at rest at START's initial_angle_deg {angle:g} (angle "
                               f"{msg.pole_angle_deg:g} deg, rate "
                               f"{msg.pole_angular_velocity_deg_per_s:g} deg/s)")
        if msg.failed:
            self.fail("reset", "the state after START is failed")
        self.steps = 0
        return msg

    def step(self, direction: int, order: str = "both") -> CartPoleState:
        """action(t-1) and clock(t); `order`: "both", "action first" or "clock first" (probe
        that neither alone makes a state), "action only" or "clock only" (the other is out)."""
        t = self.tick
        if order in ("action only", "clock only"):
            if order == "action only":
                self.node.action(t - 1, self.trial, direction)
            else:
                self.node.clock(t)
        elif order == "action first":
            self.node.action(t - 1, self.trial, direction)
            self.quiet("lockstep", f"publishes state {t} on action({t - 1}) without clock({t})")
            self.node.clock(t)
        elif order == "clock first":
            self.node.clock(t)
            self.quiet("lockstep", f"publishes state {t} on clock({t}) before action({t - 1})")
            self.node.action(t - 1, self.trial, direction)
        else:
            self.node.action(t - 1, self.trial, direction)
            self.node.clock(t)
        if self.tick != t:  # a quiet probe caught an early state; the node has moved on
            return self.last
        msg = self.await_state(f"action of tick {t - 1}")
        self.checked.add("successful_steps")
        expected = self.steps + (not msg.failed)
        if msg.successful_steps != expected:
            what = "counts the failing step" if msg.failed and \
                msg.successful_steps == self.steps + 1 else f"expected {expected}"
            self.fail("successful_steps", f"successful_steps {msg.successful_steps} at tick {t} "
                                          f"of trial {self.trial}: {what}")
        self.steps = expected
        return msg

    def probe(self, rule: str, send, what: str) -> None:
        """Send something bad with this tick's clock: no state may come."""
        self.checked.add(rule)
        send()
        self.quiet(rule, what)

    def end_trial(self) -> None:
        """The trial is over: the agent answers force 0 (no state may follow by itself)."""
        self.node.action(self.tick - 1, self.trial, 0)
        self.quiet("lockstep", f"publishes state {self.tick} on the force-0 action of tick "
                               f"{self.tick - 1} without a START")

    @staticmethod
    def balance(msg: CartPoleState) -> int:
        return 1 if msg.pole_angle_deg + 0.5 * msg.pole_angular_velocity_deg_per_s > 0 else -1

    def scenario(self) -> None:
        node = self.node
        self.quiet("lockstep", f"publishes {STATE} before any clock or START")
        msg = self.start(1.0)
        # trial 0: balance up to the cap, probing the tick protocol and the refusals
        bad_inputs = {  # tick: (send a bad input with clock(t), what taking it means)
            5: (lambda t: node.action(t - 1, self.trial, 5),
                "does not refuse an action with force_direction 5"),
            6: (lambda t: node.action(t + 3, self.trial, 1),
                "does not refuse an action of tick 9 at tick 6 (expected tick 5)"),
            7: (lambda t: node.event(TrialEvent.START, t, self.trial + 1, 0.5),
                "does not refuse a START in the middle of a trial"),
        }
        while not msg.failed and self.steps < MAX_STEPS:
            t = self.tick
            direction = self.balance(msg)
            order = {1: "action first", 2: "clock first"}.get(t, "both")
            if t in bad_inputs:
                send, what = bad_inputs[t]
                self.probe("refusals", lambda: (send(t), node.clock(t)), what)
                order = "action only"
            elif t == 8:
                self.probe("refusals", lambda: (node.clock(t + 3),
                                                node.action(t - 1, self.trial, direction)),
                           f"does not refuse clock of tick {t + 3} at tick {t}")
                order = "clock only"
            if self.tick != t:  # it took the bad input and published a state: follow it
                msg = self.last
                continue
            msg = self.step(direction, order)
        if msg.failed:
            self.problems["successful_steps"].append(
                f"not checked: the checker's controller kept the pole up for only "
                f"{msg.successful_steps} of the max_steps {MAX_STEPS} steps")
        elif msg.successful_steps > MAX_STEPS:
            self.fail("successful_steps", f"successful_steps {msg.successful_steps} passed "
                                          f"max_steps {MAX_STEPS}")
        self.end_trial()
        angle, t = ANGLE_LIMIT_DEG + 18.0, self.tick
        self.probe("refusals", lambda: (node.event(TrialEvent.START, t, self.trial + 1, angle),
                                        node.clock(t)),
                   f"does not refuse a START with initial_angle_deg {angle:g} (outside "
                   f"+-{ANGLE_LIMIT_DEG:g})")
        if self.tick != t:  # it took that START: end that trial too
            self.end_trial()
        # trial 1: constant +F until the trial fails
        msg = self.start(-0.5, "start only" if self.tick == t else "clock first")
        while not msg.failed and self.steps < MAX_STEPS:
            msg = self.step(1)
        self.checked.add("failure")
        if not msg.failed:
            self.fail("failure", f"constant +F for max_steps {MAX_STEPS} steps did not fail the "
                                 f"trial (pole at {msg.pole_angle_deg:.2f} deg, cart at "
                                 f"{msg.cart_position_m:.2f} m)")
        self.end_trial()
        # trial 2: a few steps, then the end of the episode
        msg = self.start(0.25)
        for _ in range(3):
            msg = self.step(self.balance(msg))
        node.event(TrialEvent.EPISODE_END, self.tick - 1, self.trial)
        self.checked.add("episode_end")
        try:
            status = self.process.wait(timeout=EXIT_S)
        except subprocess.TimeoutExpired:
            self.fail("episode_end", f"does not exit on EPISODE_END (still running after "
                                     f"{EXIT_S:g} s)")
        else:
            if status != 0:
                self.fail("episode_end", f"exits with status {status} on EPISODE_END")

    # -- the graph's view of the node ---------------------------------------------------------
    def environment_present(self) -> bool:
        return (NAME, self.namespace) in self.node.get_node_names_and_namespaces()

    def endpoints(self, which: str) -> str:
        """What the checked node publishes or subscribes ('publishes'/'subscribes'), for a
        FAIL line: '; it publishes /cartpole/state (clnn_ros_msgs/msg/CartPoleState), ...'."""
        lookup = self.node.get_publisher_names_and_types_by_node if which == "publishes" else \
            self.node.get_subscriber_names_and_types_by_node
        try:
            topics = lookup(NAME, self.namespace)
        except Exception:  # rclpy raises NodeNameNonExistentError (not public) for a node gone
            return ""
        shown = ", ".join(f"{name} ({'/'.join(types)})" for name, types in sorted(topics)
                          if not name.startswith(("/rosout", "/parameter_events")))
        return f"; it {which} {shown or 'nothing'}"

    def connect(self) -> None:
        node, ns = self.node, self.namespace
        # The readiness bound counts from the node's arrival: a loaded machine may take seconds
        # to start its process.
        self.spin(max(self.startup_s, APPEAR_S),
                  lambda: self.environment_present() or NAME in node.ready)
        ready = self.spin(self.startup_s, lambda: NAME in node.ready)
        self.checked.update(("starts", "readiness", "interface", "lockstep"))
        if self.process.poll() is not None:
            self.fail("starts", f"exited with status {self.process.returncode} before the "
                                f"first tick{self.stderr_tail()}")
            raise Abort
        pubs = {CLOCK: node.clock_pub, TRIAL_EVENT: node.event_pub, ACTION: node.action_pub}
        # Discovery is one-sided: the node's readers knowing the checker's writers (its
        # readiness) says nothing of the writers knowing the readers; a loaded machine takes
        # seconds for that, so it gets the start-up bound.
        self.spin(self.startup_s, lambda: all(p.get_subscription_count() for p in pubs.values())
                  and self.environment_present() and node.get_publishers_info_by_topic(STATE))
        if not ready:
            self.fail("readiness", f"no readiness announcement: no String '{NAME}' on "
                                   f"{absolute(READY, ns)} (TRANSIENT_LOCAL) within "
                                   f"{self.startup_s:g} s"
                      + (f"; it announced {sorted(set(node.ready))}" if node.ready else "")
                      + self.endpoints("publishes"))
        if not self.environment_present():
            elsewhere = sorted(n for name, n in node.get_node_names_and_namespaces()
                               if name == NAME)
            self.fail("interface", f"no node named '{NAME}' in namespace {ns}" + (
                f" (one in {', '.join(elsewhere)}: the node must take its namespace from "
                f"--ros-args -r __ns:=...)" if elsewhere else
                f" (nodes: {sorted(set(node.get_node_names()) - {node.get_name()})})"))
        for topic, publisher in pubs.items():
            if publisher.get_subscription_count():
                continue
            theirs = [i for i in node.get_subscriptions_info_by_topic(topic)
                      if i.node_name == NAME and i.node_namespace == ns]
            why = f": its subscription's QoS does not match RELIABLE, VOLATILE " \
                  f"({theirs[0].qos_profile.reliability.name}, " \
                  f"{theirs[0].qos_profile.durability.name})" if theirs else \
                  " (topic names must be relative, resolved in the node's namespace)" + \
                  self.endpoints("subscribes")
            self.fail("interface", f"does not subscribe {absolute(topic, ns)} "
                                   f"({TYPES[topic]}){why}")
        infos = node.get_publishers_info_by_topic(STATE)
        if not infos:
            self.fail("interface", f"does not publish {absolute(STATE, ns)} (topic names must "
                                   f"be relative){self.endpoints('publishes')}")
        for info in infos:
            if info.topic_type != TYPES[STATE]:
                self.fail("interface", f"publishes {STATE} as {info.topic_type}, not {TYPES[STATE]}")
            if info.qos_profile.reliability != ReliabilityPolicy.RELIABLE:
                self.fail("interface", f"publishes {STATE} {info.qos_profile.reliability.name}, "
                                       f"not RELIABLE")
            if info.qos_profile.durability != DurabilityPolicy.VOLATILE:
                self.fail("interface", f"publishes {STATE} {info.qos_profile.durability.name}, "
                                       f"not VOLATILE")
        for topic in (CLOCK, TRIAL_EVENT, ACTION):
            for info in node.get_subscriptions_info_by_topic(topic):
                if info.node_name != NAME or info.node_namespace != ns:
                    continue
                if info.topic_type != TYPES[topic]:
                    self.fail("interface", f"subscribes {topic} as {info.topic_type}, not "
                                           f"{TYPES[topic]}")
                # rclpy's TimeSource adds a BEST_EFFORT subscription to the clock
                elif info.qos_profile.reliability != ReliabilityPolicy.RELIABLE and \
                        topic != CLOCK:
                    self.fail("interface", f"subscribes {topic} "
                                           f"{info.qos_profile.reliability.name}, not RELIABLE")
        self.check_sim_time()

    def check_sim_time(self) -> None:
        """use_sim_time, read through the node's parameter services."""
        self.checked.add("sim_time")
        client = AsyncParameterClient(self.node, f"{self.namespace.rstrip('/')}/{NAME}")
        if not self.spin(self.startup_s, client.services_are_ready):
            self.fail("sim_time", "cannot read use_sim_time: its parameter services do not "
                                  f"answer within {self.startup_s:g} s")
            return
        future = resend_until_answered(lambda: client.get_parameters(["use_sim_time"]),
                                       lambda future, s: self.spin(s, future.done),
                                       self.startup_s, REPLY_S)
        if not future.done() or future.result() is None:
            self.fail("sim_time", f"cannot read use_sim_time: no answer within "
                                  f"{self.startup_s:g} s")
            return
        values = future.result().values
        if not values or values[0].type != ParameterType.PARAMETER_BOOL or \
                not values[0].bool_value:
            self.fail("sim_time", "use_sim_time is not true (the node's ROS time must be the "
                                  "graph's sim time)")

    def stderr_tail(self) -> str:
        self.stderr.flush()
        lines = [line for line in Path(self.stderr.name).read_text(errors="replace").splitlines()
                 if line.strip()]
        return f": {lines[-1].strip()}" if lines else ""

    def start_process(self, params_file: Path, env: dict) -> subprocess.Popen:
        """The command as run_all starts it: the run's ROS arguments appended, a pipe on stdin
        that is never written to."""
        arguments = ["--ros-args", "--params-file", str(params_file)]
        if self.namespace != "/":
            arguments += ["-r", f"__ns:={self.namespace}",
                          "-r", f"/clock:={self.namespace}/clock"]
        return subprocess.Popen([*self.command, *arguments], env=env, stdin=subprocess.PIPE,
                                stdout=subprocess.DEVNULL, stderr=self.stderr,
                                start_new_session=True)

    def run(self, params_file: Path, env: dict) -> None:
        context = rclpy.Context()
        # not sys.argv: the checked command's own --ros-args are not the checker's
        rclpy.init(args=[sys.argv[0]], context=context, domain_id=self.domain_id)
        self.node = Harness(context, self.namespace)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        with tempfile.NamedTemporaryFile("w+", prefix="env_node_stderr_") as self.stderr:
            self.process = self.start_process(params_file, env)
            try:
                self.connect()
                self.scenario()
            except Abort:
                pass
            finally:
                self.stop_process()
            try:
                if not self.problems["starts"]:
                    self.check_stdin_eof(params_file, env)
            finally:
                self.stop_process()
                self.node.destroy_node()
                rclpy.try_shutdown(context=context)
            self.states = list(self.node.states)
        seen = {}
        for msg in self.states:
            seen[msg.tick] = seen.get(msg.tick, 0) + 1
        for tick, count in sorted(seen.items()):
            if count > 1:
                self.fail("lockstep", f"publishes {count} states for tick {tick}")

    def check_stdin_eof(self, params_file: Path, env: dict) -> None:
        """A second start: once its node is in the graph, close its stdin; it must exit."""
        self.spin(EXIT_S, lambda: not self.environment_present())  # the first one is gone
        self.checked.add("stdin_eof")
        self.process = self.start_process(params_file, env)
        appear_s = max(self.startup_s, APPEAR_S)
        if not self.spin(appear_s, self.environment_present):
            if self.process.poll() is not None:
                self.fail("stdin_eof", f"started again, it exited with status "
                                       f"{self.process.returncode} before its stdin was closed")
            else:
                self.fail("stdin_eof", f"started again, no node '{NAME}' appeared within "
                                       f"{appear_s:g} s")
            return
        self.process.stdin.close()
        try:
            self.process.wait(timeout=EXIT_S)
        except subprocess.TimeoutExpired:
            self.fail("stdin_eof", f"does not exit when its stdin reaches end of file (still "
                                   f"running after {EXIT_S:g} s; run_all gives every node a pipe "
                                   f"on stdin and {EXIT_WITH_STDIN}=1)")

    def stop_process(self) -> None:
        """SIGINT, SIGTERM, then SIGKILL to its process group, until it has exited."""
        for sig, wait in ((signal.SIGINT, 3.0), (signal.SIGTERM, 2.0), (signal.SIGKILL, 5.0)):
            if self.process.poll() is not None:
                break
            try:
                os.killpg(self.process.pid, sig)
                self.process.wait(timeout=wait)
            except subprocess.TimeoutExpired:
                continue
            except ProcessLookupError:
                break
        self.process.stdin.close()

    def report(self) -> bool:
        ok = True
        for rule, meaning in RULES.items():
            problems = self.problems[rule]
            if rule not in self.checked:
                print(f"SKIP  {rule}: not checked (an earlier failure stopped the check)")
                ok = False
            elif problems:
                ok = False
                for text in problems:
                    print(f"FAIL  {rule}: {text}")
                if self.more.get(rule):
                    print(f"FAIL  {rule}: ... and {self.more[rule]} more like these")
            else:
                print(f"PASS  {rule}: {meaning}")
        return ok


def namespace_argument(text: str) -> str:
    """'/' or '/name[/name...]' (tokens of letters, digits and _, not starting with a digit)."""
    tokens = text.strip("/").split("/") if text.strip("/") else []
    if not all(t.isascii() and (t[0].isalpha() or t[0] == "_") and
               all(c.isalnum() or c == "_" for c in t) for t in tokens if t) or "" in tokens:
        raise argparse.ArgumentTypeError(f"{text!r} is not a ROS namespace (letters, digits and "
                                         f"_, not starting with a digit, '/' between levels)")
    return "/" + "/".join(tokens)


def main(argv: list[str] | None = None) -> int:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.check_env_node",
                                   name="check_env_node", description=__doc__.split("\n\n")[0])
    parser.add_argument("--domain-id", type=int, default=150 + os.getpid() % 80,
                        help="private ROS_DOMAIN_ID for the check (default: 150 + pid %% 80)")
    parser.add_argument("--namespace", type=namespace_argument, default="/check_env_node",
                        help="the namespace the node is started in (default /check_env_node; "
                             "/ for none)")
    parser.add_argument("--startup-timeout", type=float, default=30.0,
                        help="seconds the node gets to announce readiness once it is in the "
                             "graph, and discovery to match the checker's endpoints with the "
                             "node's")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="the node's command line")
    args = parser.parse_args(argv)
    if not args.command:
        parser.error("give the environment node's command, e.g. python -m "
                     "clnn_ros.nodes.environment")
    if args.command[0] in ("python", "python3"):  # the interpreter (venv) of the checker
        args.command[0] = sys.executable
    if not 0 <= args.domain_id <= 232:
        parser.error("--domain-id must be 0..232")
    with tempfile.TemporaryDirectory(prefix="check_env_node_") as tmp:
        params_file = Path(tmp) / "params.yaml"
        params_file.write_text(f"/**:\n  ros__parameters:\n    max_steps: {MAX_STEPS}\n")
        env = {**os.environ, "ROS_DOMAIN_ID": str(args.domain_id), EXIT_WITH_STDIN: "1",
               "ROS_AUTOMATIC_DISCOVERY_RANGE": os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE",
                                                               "LOCALHOST")}
        env.setdefault("ROS_LOG_DIR", str(Path(tmp) / "ros_log"))
        checker = Checker(args.command, args.domain_id, args.startup_timeout, args.namespace)
        print(f"check_env_node: {' '.join(args.command)} (ROS_DOMAIN_ID {args.domain_id}, "
              f"namespace {args.namespace}, max_steps {MAX_STEPS})", flush=True)
        checker.run(params_file, env)
    ok = checker.report()
    print(f"check_env_node: {'all rules pass' if ok else 'the node breaks the contract'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
