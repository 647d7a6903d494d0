"""The checker's hands: the checked command in a process of its own, started as run_all starts
an environment node, and a harness node in its namespace that plays trial manager and agent and
sees what the graph sees of it. Only public rclpy."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from ..session import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from clnn_ros_msgs.msg import Action, Observation, TaskDescription, TrialEvent

from ..graph import qos
from ..graph.fields import tick_stamp
from ..graph.names import ACTION, CLOCK, OLDER_STATE, READY, STATE, TASK, TRIAL_EVENT
from ..session.rclpy_session import qos_profile
from .rules import NAME, TAU_NS

# The names of an older environment contract's messages and fields, and which version had them
# last (docs/ENV_CONTRACT.md, "Versions"): a node written against it fails on them.
OLDER_NAMES = {"header": "version 1", "failed": "version 1", "failure_reason": "version 1",
               "CartPoleState": "version 3", "force_direction": "version 3",
               "force_n": "version 3", "winning_neuron": "version 3", "failure": "version 3",
               "FAILURE_NONE": "version 3", "cart_position_m": "version 3"}

LOCKSTEP_QOS = qos_profile(qos.LOCKSTEP)
READY_QOS = qos_profile(qos.READY)
TASK_QOS = qos_profile(qos.LABELS)  # the graph's subscriptions to env/task
QUIET_S = 0.3  # how long "no observation may come" is watched
REPLY_S = 5.0  # how long an answer may take (an observation, a parameter service's)
# How long the node gets to exit (EPISODE_END, end of stdin): its own exit waits up to 2 s for
# its last messages' acknowledgements, then deletes its participant; beside CPU hogs a good node
# took more than 5 s.
EXIT_S = 15.0
APPEAR_S = 20.0  # at least this long for the node to appear in the graph (at start, again)
# SIGINT, then SIGTERM, then SIGKILL to the checked process group, each given this long to end it
STOP_SIGNALS = ((signal.SIGINT, 3.0), (signal.SIGTERM, 2.0), (signal.SIGKILL, 5.0))


class Harness(Node):
    """Trial manager + agent, in the checked node's namespace: publishes clock, trial/event and
    rln/action, reads the task and the observations (the graph does not check who sends a
    message)."""

    def __init__(self, context, namespace: str):
        super().__init__("check_env_node", context=context, namespace=namespace)
        self.clock_pub = self.create_publisher(Clock, CLOCK, LOCKSTEP_QOS)
        self.event_pub = self.create_publisher(TrialEvent, TRIAL_EVENT, LOCKSTEP_QOS)
        self.action_pub = self.create_publisher(Action, ACTION, LOCKSTEP_QOS)
        self.states: list[Observation] = []
        self.ready: list[str] = []
        self.tasks: list[TaskDescription] = []
        # three subscriptions: the encoder, reward and trial manager a real graph has
        self.create_subscription(Observation, STATE, self.states.append, LOCKSTEP_QOS)
        for _ in range(2):
            self.create_subscription(Observation, STATE, lambda _msg: None, LOCKSTEP_QOS)
        self.create_subscription(String, READY, lambda m: self.ready.append(m.data), READY_QOS)
        self.create_subscription(TaskDescription, TASK, self.tasks.append, TASK_QOS)

    def late_task(self) -> list[TaskDescription]:
        """A subscription to env/task made now, as a node that joins later makes it: what it
        receives (a latched description, from the publisher's history)."""
        received = []
        self.create_subscription(TaskDescription, TASK, received.append, TASK_QOS)
        return received

    def older_state_publishers(self) -> list:
        """The publishers on cartpole/state in the namespace: an older contract's node."""
        return self.get_publishers_info_by_topic(OLDER_STATE)

    def clock(self, tick: int) -> None:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = tick_stamp(tick, TAU_NS)
        self.clock_pub.publish(msg)

    def event(self, kind: int, tick: int, trial: int, angle: float = 0.0) -> None:
        self.event_pub.publish(TrialEvent(tick=tick, trial=trial, event=kind,
                                          initial_angle_deg=angle))

    def action(self, tick: int, trial: int, action: int) -> None:
        """The action of index `action` (Action.ACTION_NONE: the answer to a trial's last
        observation)."""
        self.action_pub.publish(Action(tick=tick, trial=trial, action=action))


class Probe:
    """The checked command and the harness node, in a private ROS domain (`env` sets it)."""

    def __init__(self, command: list[str], namespace: str, domain_id: int, startup_s: float,
                 params_file: Path, env: dict):
        self.command, self.namespace, self.domain_id = command, namespace, domain_id
        self.startup_s, self.params_file, self.env = startup_s, params_file, env
        self.process: subprocess.Popen | None = None

    @contextmanager
    def session(self) -> Iterator[Probe]:
        """The harness node on an executor of its own context (not sys.argv: the checked
        command's own --ros-args are not the checker's); on the way out the process is
        stopped."""
        context = rclpy.Context()
        rclpy.init(args=[sys.argv[0]], context=context, domain_id=self.domain_id)
        self.node = Harness(context, self.namespace)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        with tempfile.NamedTemporaryFile("w+", prefix="env_node_stderr_") as self.stderr:
            try:
                yield self
            finally:
                self.stop_process()
                # The harness node and its DDS participant are not deleted: Fast DDS 2.14 can
                # deadlock deleting a participant while its discovery thread takes in a peer's
                # leaving (docs/ROS_GRAPH.md; seen here under load: minutes of a spinning
                # checker). The checker leaves them to its process's end (live/check_env.py).

    def start_process(self) -> None:
        """The command as run_all starts it: the run's ROS arguments appended, a pipe on stdin
        that is never written to."""
        arguments = ["--ros-args", "--params-file", str(self.params_file)]
        if self.namespace != "/":
            arguments += ["-r", f"__ns:={self.namespace}",
                          "-r", f"/clock:={self.namespace}/clock"]
        self.process = subprocess.Popen([*self.command, *arguments], env=self.env,
                                        stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                        stderr=self.stderr, start_new_session=True)

    def stop_process(self) -> None:
        """STOP_SIGNALS to its process group, until it has exited."""
        if self.process is None:
            return
        for sig, wait in STOP_SIGNALS:
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

    def spin(self, seconds: float, until: Callable[[], bool] = lambda: False) -> bool:
        """Spin the harness until `until()` holds (True), `seconds` pass or the process exits."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            if until():
                return True
            self.executor.spin_once(timeout_sec=0.01)
            if self.process.poll() is not None:
                return until()
        return until()

    def exit_status(self) -> str:
        """' (the process exited with status N: <its last stderr line>)', or '' while it runs."""
        status = self.process.poll()
        return f" (the process exited with status {status}{self.stderr_tail()})" \
            if status is not None else ""

    def stderr_tail(self) -> str:
        """': <the last line the process wrote to stderr>', or ''; a message or field of an
        older version of the contract is named as such."""
        self.stderr.flush()
        lines = [line for line in Path(self.stderr.name).read_text(errors="replace").splitlines()
                 if line.strip()]
        if not lines:
            return ""
        older = [f"{name} ({version})" for name, version in OLDER_NAMES.items()
                 if ("AttributeError" in lines[-1] or "ImportError" in lines[-1]) and
                 f"'{name}'" in lines[-1]]
        return f": {lines[-1].strip()}" + (
            f" (a name of an older contract: {older[0]}; docs/ENV_CONTRACT.md, Versions)"
            if older else "")

    def environment_present(self) -> bool:
        return (NAME, self.namespace) in self.node.get_node_names_and_namespaces()

    def endpoints(self, which: str) -> str:
        """What the checked node publishes or subscribes ('publishes'/'subscribes'), for a
        FAIL line: '; it publishes /env/observation (clnn_ros_msgs/msg/Observation), ...'."""
        lookup = self.node.get_publisher_names_and_types_by_node if which == "publishes" else \
            self.node.get_subscriber_names_and_types_by_node
        try:
            topics = lookup(NAME, self.namespace)
        except Exception:  # rclpy raises NodeNameNonExistentError (not public) for a node gone
            return ""
        shown = ", ".join(f"{name} ({'/'.join(types)})" for name, types in sorted(topics)
                          if not name.startswith(("/rosout", "/parameter_events")))
        return f"; it {which} {shown or 'nothing'}"
