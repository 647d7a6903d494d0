"""Ask the running graph's agent to save a checkpoint now, like
`ros2 service call /agent/save_checkpoint std_srvs/srv/Trigger` (--namespace NAME: the graph
of `run_all --namespace NAME`, /NAME/agent/save_checkpoint).

    python -m clnn_ros.live.save_checkpoint       # prints <out_dir>/checkpoint_<tick>.npz

The agent saves its state after the last tick it completed; `run_all --init-weights FILE` resumes
from it. Exit status 0 saved, 1 the agent refused (the reason is printed), 2 no agent answered
within --wait seconds, 130 on Ctrl-C.
"""

from __future__ import annotations

import sys
import time

from ..session import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)

import rclpy
from std_srvs.srv import Trigger

from ..cli import OneLineArgumentParser
from ..session.rclpy_session import exit_keeping_participant, ros_session


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.live.save_checkpoint",
                                   name="save_checkpoint",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("--wait", type=float, default=10.0,
                        help="seconds to wait for the agent's answer (10)")
    parser.add_argument("--namespace", default="/", help="the graph's namespace (/)")
    args = parser.parse_args(argv)
    service = "/" + "/".join(filter(None, [*args.namespace.split("/"), "agent",
                                           "save_checkpoint"]))
    with ros_session() as received:
        node = rclpy.create_node("save_checkpoint", start_parameter_services=False,
                                 enable_rosout=False)
        exit_keeping_participant(node, request_checkpoint(node, service, args.wait, received))


def request_checkpoint(node, service: str, wait_s: float, received: list[int]) -> int:
    """Ask the agent to save a checkpoint; returns the exit status."""
    client = node.create_client(Trigger, service)
    deadline = time.monotonic() + wait_s
    future = None
    while not received and time.monotonic() < deadline:
        if future is None and client.service_is_ready():
            future = client.call_async(Trigger.Request())
        rclpy.spin_once(node, timeout_sec=0.05)
        if future is not None and future.done():
            response = future.result()
            print(response.message, file=sys.stdout if response.success else sys.stderr)
            return 0 if response.success else 1
    if received:
        return 128 + received[0]
    print(f"save_checkpoint: error: no agent answered on {service} within "
          f"{wait_s:g} s (is the graph running on this ROS_DOMAIN_ID?)",
          file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
