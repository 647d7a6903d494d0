"""The QoS of the graph's topics, as plain descriptions: no ROS import, so offline tools and
benchmarks read them without rclpy. A node builds its rclpy QoSProfile from one
(clnn_ros.session.rclpy_session.qos_profile). The policy names are those of rclpy's enums in lower
case,
as rosbag2 writes them.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Qos:
    depth: int
    reliability: str = "reliable"  # or "best_effort"
    durability: str = "volatile"  # or "transient_local"
    history: str = "keep_last"


# In lockstep a publisher is never more than a few messages ahead of any node of the graph (at
# most END, EPISODE_END and START on trial/event within one tick). A subscriber outside the
# lockstep (echo, the recorder) may lag: the publisher's history keeps the last 2000 messages
# for it (about 1 s of the graph); the recorder also holds the graph back
# (RECORDER_WINDOW).
LOCKSTEP = Qos(depth=2000)
# The recorder's progress: only its latest tick matters.
PROGRESS = Qos(depth=1)
# A readiness announcement must reach a trial manager that starts later than the node; the
# depth keeps every node's announcement when several arrive at once.
READY = Qos(depth=16, durability="transient_local")
# A trial manager's claim: published once, kept for the trial manager of a graph that starts
# later. Every claim is kept until taken (keep_all): the topic has no key, so a keep_last reader
# keeps the last `depth` samples of all its publishers together, and a claim arriving with the
# reader's own (or a third graph's) replaced it before rclpy took it (of two graphs started
# together, one never heard the other's claim; 12 participants started at once: 25-44 of 132
# claims lost with depth 1, on UDP and on rmw's shared memory alike; none with a deeper reader).
CLAIM = Qos(depth=1, durability="transient_local", history="keep_all")
# The input labels: published once, kept for whoever subscribes later (echo --raster).
LABELS = Qos(depth=1, durability="transient_local")
# The recorder's subscriptions: deep enough that the DDS receive thread never drops a message
# while Python is busy, so the recorder may lag behind the lockstep graph without loss.
RECORD = Qos(depth=100_000)
# echo's subscription: it may print slower than the graph runs.
ECHO = Qos(depth=1000)
# The recorder's progress (the last tick it holds on every per-tick topic): the trial manager
# keeps the graph at most RECORDER_WINDOW ticks ahead of it, far less than the publishers'
# history, so a slow recorder slows the graph down instead of losing messages.
RECORDER_WINDOW = 500
# Seen once in a suite beside CPU hogs: the trial manager never took the recorder's one
# announcement (TRANSIENT_LOCAL, reliable; a reader that joined later got it) and waited for it.
READY_REPEAT_S = 1.0
