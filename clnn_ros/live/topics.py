"""List the topics of the running graph with their types, like `ros2 topic list -t`.

    python -m clnn_ros.live.topics            # /env/observation [clnn_ros_msgs/msg/Observation]
    ...
    python -m clnn_ros.live.topics --count    # and how many publishers and subscribers each has

It listens (DDS discovery) on this ROS_DOMAIN_ID until what it has found is complete and
settled, prints, exits. Complete: every endpoint's node has announced itself and every node
announced has endpoints (on a loaded machine a participant's endpoints can come seconds after
its announcement, or before it). Settled: nothing changed for as long as discovery had taken
until the last change and at least 4 s (a participant announces itself every 3 s), so a slow
machine is given proportionally longer. Its own endpoints are not counted. Exit status 0 (a
warning line if it gave up after --wait); 130 on Ctrl-C.
"""

from __future__ import annotations

import os
import sys
import time

from ..session import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)

from ..cli import OneLineArgumentParser

# A participant announces itself every 3 s (Fast DDS's default announcement period); one that
# missed this tool's first announcements is seen at its next one, so a quieter spell than that is
# no proof that discovery is over (seen on a loaded machine: a third participant missed).
MIN_QUIET_S = 4.0
# How long it listens at most. Beside runs starting and ending on another domain (2 cores), 3 of
# 40 listings of a running graph found their first participant only after 10 s (up to 12.8 s;
# each listed the whole graph within 32 s), the others within 2.7 s. It prints as soon as
# discovery has settled, so the bound costs time only when nothing runs.
DEFAULT_WAIT_S = 30.0


def graph_view(node) -> tuple[dict, bool]:
    """What discovery has found, but this node's own endpoints: {topic: (types, publishers,
    subscribers)}, each endpoint as (node namespace, node name, gid); and whether it is
    complete: the nodes that own the endpoints are the nodes announced (an endpoint whose node
    has not announced it has rmw's placeholder name)."""
    me = (node.get_namespace(), node.get_name())
    view, owners = {}, set()
    for name, types in node.get_topic_names_and_types():
        publishers, subscribers = (
            frozenset((e.node_namespace, e.node_name, tuple(e.endpoint_gid)) for e in endpoints
                      if (e.node_namespace, e.node_name) != me)
            for endpoints in (node.get_publishers_info_by_topic(name),
                              node.get_subscriptions_info_by_topic(name)))
        if publishers or subscribers:
            view[name] = (tuple(types), publishers, subscribers)
            owners |= {(namespace, owner) for namespace, owner, _ in publishers | subscribers}
    announced = {(namespace, name) for name, namespace in node.get_node_names_and_namespaces()}
    return view, owners == announced - {me}


def discover(node, wait_s: float, received: list[int]) -> tuple[dict, bool]:
    """The graph view once complete and settled, or after wait_s; and whether it settled."""
    import rclpy
    start = last_change = time.monotonic()
    view = {}
    while not received:
        rclpy.spin_once(node, timeout_sec=0.1)
        now = time.monotonic()
        found, complete = graph_view(node)
        if found != view:
            view, last_change = found, now
        if view and complete and now - last_change >= max(MIN_QUIET_S, last_change - start):
            return view, True
        if now - start > wait_s:
            break
    return view, False


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.live.topics", name="topics",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", action="store_true",
                        help="also the number of publishers and subscribers")
    parser.add_argument("--wait", type=float, default=DEFAULT_WAIT_S,
                        help=f"at most this many seconds of discovery ({DEFAULT_WAIT_S:g}); it "
                             f"lists as soon as what it found is complete and settled")
    parser.add_argument("--include-hidden-topics", action="store_true",
                        help="also the plumbing (names with a part starting with _)")
    args = parser.parse_args(argv)
    import rclpy  # after the arguments: --help and a usage error need no ROS
    from ..session.rclpy_session import exit_keeping_participant, ros_session
    with ros_session() as received:
        # hidden (ROS's convention) and this process's own: its endpoints are left out
        node = rclpy.create_node(f"_topics_{os.getpid()}", start_parameter_services=False,
                                 enable_rosout=False)
        exit_keeping_participant(node, list_topics(node, args, received))


def list_topics(node, args, received: list[int]) -> int:
    """Print the topics found; returns the exit status."""
    from rclpy.topic_or_service_is_hidden import topic_or_service_is_hidden
    try:
        view, settled = discover(node, args.wait, received)
        if received:
            return 128 + received[0]
        if not settled:
            print(f"topics: warning: discovery had not settled after {args.wait:g} s "
                  f"(--wait): the list may be incomplete" if view else
                  f"topics: no other participant found in {args.wait:g} s on this "
                  f"ROS_DOMAIN_ID", file=sys.stderr)
        for name, (types, publishers, subscribers) in sorted(view.items()):
            if not args.include_hidden_topics and topic_or_service_is_hidden(name):
                continue
            line = f"{name} [{', '.join(types)}]"
            if args.count:
                line += f"  publishers {len(publishers)}, subscribers {len(subscribers)}"
            print(line)
        return 0
    except BrokenPipeError:
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
