"""The raw DDS ring of the benchmark (scripts/benchmark_graph.py): five nodes that exchange
exactly the lockstep messages of the graph's tick (bench_settings.EDGES, NEEDS) and do nothing
else, with the graph's QoS and executor factory; in five processes (ring_stage, one role each)
or composed in one (ring_composed). The trial manager's process prints the result as one line
`RING_RESULT {json}`."""

from __future__ import annotations

import json
import sys
import time

from bench_settings import EDGES, NEEDS, RING_NS, ROLES, RUN_TIMEOUT_S

# ----------------------------------------------------------------------------- raw ring nodes

def ring_messages(kind: str) -> dict:
    """One reusable message per topic: std_msgs/UInt64, or the graph's types with the content
    of a typical tick (fixed: no model work)."""
    if kind == "uint64":
        from std_msgs.msg import UInt64
        return {topic: UInt64() for topic in EDGES}
    from clnn_ros_msgs.msg import Action, Observation, Reward, SpikeVector
    from rosgraph_msgs.msg import Clock

    return {
        "clock": Clock(),
        # the cart-pole's observation: cart position, cart velocity, pole angle, angular velocity
        "state": Observation(values=[0.01, 0.1, -0.5, 3.0], successful_steps=100),
        "spikes": SpikeVector(spikes=[0, 0, 1, 0, 0, 0]),
        "reward": Reward(reward_one_hot=[0, 0], success_counter=100),
        "action": Action(action=1, winning_segment=3),
    }


def ring_node(role: str, kind: str, ticks: int):
    import rclpy.node
    from rclpy.task import Future

    from clnn_ros.nodes.glue import LOCKSTEP_QOS as qos  # the graph's QoS, depth and all

    out_topic = next(t for t, (publisher, _) in EDGES.items() if publisher == role)
    in_topics = [t for t, (_, subscribers) in EDGES.items() if role in subscribers]
    messages = ring_messages(kind)

    class RingNode(rclpy.node.Node):
        def __init__(self):
            super().__init__(f"ring_{role}")
            self.msg = messages[out_topic]
            self.uint64 = kind == "uint64"
            self.is_clock = out_topic == "clock"
            self.pub = self.create_publisher(type(self.msg), f"{RING_NS}/{out_topic}", qos)
            self.expected_subscribers = len(EDGES[out_topic][1])
            self.counts = dict.fromkeys(in_topics, 0)
            self.needs = NEEDS[role]
            self.limit = ticks if role == "trial_manager" else None
            self.sent = 0
            self.finished = Future()
            self.started = self.ended = 0.0
            self.subs = [self.create_subscription(type(messages[t]), f"{RING_NS}/{t}",
                                                  self.receiver(t), qos) for t in in_topics]

        def matched(self) -> bool:
            return (self.pub.get_subscription_count() >= self.expected_subscribers
                    and all(s.get_publisher_count() >= 1 for s in self.subs))

        def receiver(self, topic):
            def receive(_msg):
                self.counts[topic] += 1
                self.advance()
            return receive

        def advance(self) -> None:
            counts, needs = self.counts, self.needs
            while all(counts[t] >= self.sent + 1 - lag for t, lag in needs):
                if self.limit is not None and self.sent >= self.limit:
                    self.ended = time.perf_counter()
                    if not self.finished.done():
                        self.finished.set_result(True)
                    return
                self.publish(self.sent)
                self.sent += 1

        def publish(self, k: int) -> None:
            msg = self.msg
            if self.uint64:
                msg.data = k
            elif self.is_clock:
                msg.clock.sec, msg.clock.nanosec = divmod(k * 20_000_000, 1_000_000_000)
            else:
                msg.tick = k
            self.pub.publish(msg)

        def start(self) -> None:
            self.started = time.perf_counter()
            self.advance()  # clock(0)

    return RingNode()


def spin_until(executor, done, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    return done()


def ring_result(tm, ticks: int) -> None:
    wall = tm.ended - tm.started
    print("RING_RESULT " + json.dumps({"ticks": ticks, "wall_s": wall,
                                       "ticks_per_s": ticks / wall}), flush=True)


def ring_composed(a) -> int:
    """All five ring nodes in one process, one executor."""
    from clnn_ros.session.rclpy_session import ros_session
    from clnn_ros.session.rclpy_session import make_executor
    with ros_session([sys.argv[0]]):
        nodes = {role: ring_node(role, a.msgs, a.ticks) for role in ROLES}
        executor = make_executor()
        for node in nodes.values():
            executor.add_node(node)
        tm = nodes["trial_manager"]
        if not spin_until(executor, lambda: all(n.matched() for n in nodes.values()), 30):
            print("ring: discovery timed out", file=sys.stderr)
            ok = False
        else:
            tm.start()
            ok = spin_until(executor, tm.finished.done, RUN_TIMEOUT_S)
        if ok:
            ring_result(tm, a.ticks)
        executor.shutdown()
        for node in nodes.values():
            node.destroy_node()
    return 0 if ok else 1


def ring_stage(a) -> int:
    """One ring node in this process. Each node announces on a latched topic once its
    publisher and subscriptions have matched; the trial manager starts when all have, and
    ends the run with a latched stop message."""
    from rclpy.duration import Duration
    from clnn_ros.nodes.glue import READY_QOS
    from clnn_ros.session.rclpy_session import ros_session
    from clnn_ros.session.rclpy_session import make_executor
    from std_msgs.msg import String

    with ros_session([sys.argv[0]]):
        node = ring_node(a.role, a.msgs, a.ticks)
        executor = make_executor()
        executor.add_node(node)
        status = 0
        if a.role == "trial_manager":
            ready = set()
            node.create_subscription(String, f"{RING_NS}/ready", lambda m: ready.add(m.data),
                                     READY_QOS)
            stop = node.create_publisher(String, f"{RING_NS}/stop", READY_QOS)
            all_ready = lambda: len(ready) == len(ROLES) - 1 and node.matched()  # noqa: E731
            if not spin_until(executor, all_ready, 30):
                print(f"ring: discovery timed out (ready: {sorted(ready)})", file=sys.stderr)
                status = 1
            else:
                node.start()
                if spin_until(executor, node.finished.done, RUN_TIMEOUT_S):
                    ring_result(node, a.ticks)
                else:
                    print(f"ring: stalled after {node.sent} ticks", file=sys.stderr)
                    status = 1
            stop.publish(String(data="stop"))
            stop.wait_for_all_acked(Duration(seconds=2.0))
        else:
            stopped = []
            node.create_subscription(String, f"{RING_NS}/stop", stopped.append, READY_QOS)
            ready = node.create_publisher(String, f"{RING_NS}/ready", READY_QOS)
            announced = False
            deadline = time.monotonic() + RUN_TIMEOUT_S + 30
            while not stopped and time.monotonic() < deadline:
                if not announced and node.matched():
                    ready.publish(String(data=a.role))
                    announced = True
                executor.spin_once(timeout_sec=0.02 if not announced else 0.1)
            status = 0 if stopped else 1
        executor.shutdown()
        node.destroy_node()
    return status
