"""Environment defaults for every process the project starts, applied before rclpy loads:
DDS discovery stays on the loopback interface unless the user chose otherwise."""

import os

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
