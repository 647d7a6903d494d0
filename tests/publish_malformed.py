"""Publishes malformed messages into a running graph (used by test_graph.py): spike vectors of
the wrong size, with a wrong tick or not 1-hot, impossible actions and inconsistent rewards.
Waits until every node of the graph announced itself ready, sends them over about two seconds, exits 0."""

import time

from clnn_ros import rosenv  # noqa: F401

import rclpy
from clnn_ros_msgs.msg import Action, Reward, SpikeVector

from std_msgs.msg import String

from clnn_ros.nodes.common import (ACTION, GRAPH_NODES, LOCKSTEP_QOS, READY, READY_QOS, REWARD,
                                   SPIKES)

BAD = [
    (SpikeVector, SPIKES, dict(tick=0, spikes=[1, 0, 0, 0, 0, 0, 0, 0])),  # 8 inputs, not 6
    (SpikeVector, SPIKES, dict(tick=10**9, spikes=[0, 0, 1, 0, 0, 0])),  # a future tick
    (SpikeVector, SPIKES, dict(tick=0, spikes=[1, 1, 0, 0, 0, 0])),  # two angle intervals
    (Action, ACTION, dict(tick=0, force_direction=7)),
    (Reward, REWARD, dict(tick=0, kind="jackpot", reward_one_hot=[1, 1])),
]


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("malformed_publisher")
    publishers = {topic: node.create_publisher(kind, topic, LOCKSTEP_QOS) for kind, topic, _ in BAD}
    ready = set()
    node.create_subscription(String, READY, lambda msg: ready.add(msg.data), READY_QOS)
    deadline = time.monotonic() + 30
    while not ready >= set(GRAPH_NODES):  # every node of the graph is up and matched
        assert time.monotonic() < deadline, f"the graph did not come up: {sorted(ready)}"
        rclpy.spin_once(node, timeout_sec=0.05)
    while any(p.get_subscription_count() < 2 for p in publishers.values()):
        assert time.monotonic() < deadline, "no subscribers for the malformed messages"
        time.sleep(0.05)
    time.sleep(0.5)  # the episode is running
    for _ in range(10):
        for kind, topic, fields in BAD:
            publishers[topic].publish(kind(**fields))
        time.sleep(0.15)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
