"""List the topics of the running graph with their types, like `ros2 topic list -t`.

    python -m clnn_ros.topics            # /cartpole/state [clnn_ros_msgs/msg/CartPoleState] ...
    python -m clnn_ros.topics --count    # and how many publishers and subscribers each has

It listens (DDS discovery) on this ROS_DOMAIN_ID until the topic list is stable, prints, exits.
Exit status 0; 130 on Ctrl-C.
"""

from __future__ import annotations

import sys
import time

from . import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)

from .cli import OneLineArgumentParser

OWN = {"/parameter_events", "/rosout"}  # this tool's own node has these


def is_hidden(name: str) -> bool:
    """ROS's convention: a name with a part starting with _ is hidden."""
    return any(part.startswith("_") for part in name.split("/"))


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.topics", name="topics",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", action="store_true",
                        help="also the number of publishers and subscribers")
    parser.add_argument("--wait", type=float, default=5.0,
                        help="at most this many seconds of discovery (5); it lists as soon as "
                             "the graph's topics have been stable for 1 s")
    parser.add_argument("--include-hidden-topics", action="store_true",
                        help="also the plumbing (names with a part starting with _)")
    args = parser.parse_args(argv)
    import rclpy  # after the arguments: --help and a usage error need no ROS
    from .nodes.common import ros_session
    with ros_session() as received:
        node = rclpy.create_node("topics", start_parameter_services=False, enable_rosout=False)
        try:
            start = changed = time.monotonic()
            seen = set()
            while not received:  # until --wait, or once other topics appeared and stay the same 1 s
                rclpy.spin_once(node, timeout_sec=0.05)
                now = time.monotonic()
                names = {name for name, _ in node.get_topic_names_and_types()}
                if names != seen:
                    seen, changed = names, now
                if now - start > args.wait or (names - OWN and now - changed > 1.0):
                    break
            if received:
                return 128 + received[0]
            for name, types in sorted(node.get_topic_names_and_types()):
                if not args.include_hidden_topics and is_hidden(name):
                    continue
                line = f"{name} [{', '.join(types)}]"
                if args.count:
                    line += (f"  publishers {node.count_publishers(name)}, subscribers "
                             f"{node.count_subscribers(name)}")
                print(line)
            return 0
        except BrokenPipeError:
            sys.stderr.close()
            return 0
        finally:
            node.destroy_node()

if __name__ == "__main__":
    sys.exit(main())
