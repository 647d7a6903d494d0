"""A participant for tests/test_echo.py: NODES nodes in this process, each publishing the same
message on TOPIC every 50 ms and subscribing to it, until its standard input closes. Prints
"ready" once its entities exist.

    python tests/probe_participant.py TOPIC TYPE FIELDS [NODES]
    # TYPE: pkg/msg/Name; FIELDS: the message's field values as YAML, nested for messages
"""

import os
import sys
import threading

import rclpy
import yaml
from rclpy.executors import SingleThreadedExecutor

from clnn_ros.bag import message_class


def filled(cls, fields: dict):
    msg = cls()
    for name, value in fields.items():
        current = getattr(msg, name)
        setattr(msg, name, filled(type(current), value) if isinstance(value, dict) else value)
    return msg


def main(topic: str, type_name: str, fields: str, nodes: str = "1") -> None:
    cls = message_class(type_name)
    msg = filled(cls, yaml.safe_load(fields))
    rclpy.init()
    executor = SingleThreadedExecutor()
    for index in range(int(nodes)):
        node = rclpy.create_node(f"probe_{os.getpid()}_{index}")
        publisher = node.create_publisher(cls, topic, 10)
        node.create_subscription(cls, topic, lambda _msg: None, 10)
        node.create_timer(0.05, lambda publisher=publisher: publisher.publish(msg))
        executor.add_node(node)
    print("ready", flush=True)
    stdin_closed = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), stdin_closed.set()), daemon=True).start()
    while not stdin_closed.is_set():
        executor.spin_once(timeout_sec=0.1)
    rclpy.shutdown()


if __name__ == "__main__":
    main(*sys.argv[1:])
