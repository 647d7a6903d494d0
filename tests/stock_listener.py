"""A stock ROS 2 process: plain rclpy with ROS's own defaults (no clnn_ros import, so no project
profile: Fast DDS's shared memory and UDP, as `ros2 topic echo` of an installed Jazzy). It
subscribes to /rln/spikes and prints the ticks it received, one line, once it has COUNT of them
or WAIT_S has passed.

    python stock_listener.py COUNT WAIT_S
"""

import sys
import time

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy

from clnn_ros_msgs.msg import SpikeVector

count, wait_s = int(sys.argv[1]), float(sys.argv[2])
rclpy.init()
node = rclpy.create_node("stock_listener")
ticks = []
node.create_subscription(SpikeVector, "/rln/spikes", lambda message: ticks.append(message.tick),
                         QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
deadline = time.monotonic() + wait_s
while len(ticks) < count and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
print(" ".join(map(str, ticks[:count])), flush=True)
node.destroy_node()
rclpy.shutdown()
