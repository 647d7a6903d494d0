"""Print the live messages of a topic as `ros2 topic echo` does (no ROS CLI is needed: rclpy
only). Run it against a graph started in another terminal (same ROS_DOMAIN_ID).

    python -m clnn_ros.live.echo /env/observation
    python -m clnn_ros.live.echo /env/task --once            # the task (latched): variable_names...
    python -m clnn_ros.live.echo /rln/action --once          # action: the task's action index
    python -m clnn_ros.live.echo /env/observation --field values     # in variable_names' order
    python -m clnn_ros.live.echo /env/observation --field 'values[2]'  # one: the cart-pole's
                                                                       # pole angle (deg)
    python -m clnn_ros.live.echo /rln/spikes --flow-style    # {tick: 12, trial: 0, spikes: [0, 1]}
    python -m clnn_ros.live.echo /env/observation --csv       # one line per message, for plotting
    python -m clnn_ros.live.echo /rln/spikes --raster        # one row per tick: tick 12 trial 0
    |..#.|

As ros2topic's echo (rosidl_runtime_py's message_to_yaml and message_to_csv): YAML in block
style, fields in declaration order, `---` after each message, `{}` for a message without fields;
--flow-style: collections inline; --csv: every field, nested ones flattened, comma-separated,
no separator. The graph's topics are known in advance (echo may start before the graph); any
other topic must be published within --wait seconds. --field takes a field's name (nested:
clock.sec) and an element of a sequence by its index (values[2]). Exit status: 0 after --once,
130 on Ctrl-C, 1 for an unknown topic or field (or an index a message does not reach), 2 for
bad options.
"""

from __future__ import annotations

import array
import re
import sys
import time

from ..session import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)

import yaml

from ..bag import message_class
from ..cli import OneLineArgumentParser
from ..graph import qos
from ..graph.names import INPUT_LABELS, LATCHED, SPIKES, TOPIC_TYPES, absolute, graph_topic


class EchoError(Exception):
    pass


def _is_message(value) -> bool:
    return hasattr(value, "get_fields_and_field_types")


def to_plain(value):
    """A message as nested dicts (fields in declaration order) and lists of Python scalars, as
    rosidl_runtime_py's message_to_ordereddict makes it: a byte is its character."""
    if _is_message(value):
        return {name: to_plain(getattr(value, name)) for name in value.get_fields_and_field_types()}
    if isinstance(value, bytes):
        return "".join(map(chr, value))
    if hasattr(value, "tolist"):  # array.array, a numpy array or number
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return [to_plain(item) for item in value]
    return value


def to_yaml(value, flow_style: bool = False) -> str:
    """A message (or one field of it) as message_to_yaml writes it, ending in a newline."""
    text = yaml.safe_dump(to_plain(value), default_flow_style=flow_style, sort_keys=False,
                          allow_unicode=True, width=sys.maxsize)
    return text.removesuffix("...\n")  # a lone scalar: no end-of-document marker


def to_csv(value) -> str:
    """A message (or one field of it) as message_to_csv writes it: every leaf, depth first,
    comma-separated, as Python's str() writes it (True, 0.5, b'x')."""
    if _is_message(value):
        return ",".join(to_csv(getattr(value, name)) for name in value.get_fields_and_field_types())
    if isinstance(value, (list, tuple, array.array)) or getattr(value, "ndim", 0):
        return ",".join(to_csv(item) for item in value)
    return str(value)


FIELD_PART = re.compile(r"(\w+)(?:\[(\d+)\])?")


def get_field(msg, path: str, indexed: bool = True):
    """The field `path` of `msg`: names separated by dots (clock.sec), a sequence's element by
    its index (values[2]). EchoError (one line) for an unknown name, or, if `indexed`, an index
    the message's sequence does not reach (without: the names alone are checked, as before any
    message comes)."""
    value = msg
    for part in path.split("."):
        match = FIELD_PART.fullmatch(part)
        name = match.group(1) if match else part
        if not _is_message(value) or name not in value.get_fields_and_field_types():
            known = ", ".join(value.get_fields_and_field_types()) if _is_message(value) else "none"
            raise EchoError(f"no field '{name}' in --field {path} (fields there: {known})")
        value = getattr(value, name)
        if match and match.group(2) is not None:
            if not hasattr(value, "__len__") or isinstance(value, str):
                raise EchoError(f"'{name}' in --field {path} is not a sequence: no [index]")
            if not indexed:  # an empty message's sequence: what follows is checked per message
                return value
            index = int(match.group(2))
            if index >= len(value):
                raise EchoError(f"no element {index} in --field {path}: '{name}' has "
                                f"{len(value)} elements")
            value = value[index]
    return value


class Raster:
    """/rln/spikes as one text row per tick; the input labels (rln/input_labels, latched) as a
    header, again whenever they change (input numbers until they are known)."""

    def __init__(self, out):
        self.out, self.labels, self.shown = out, None, None

    def set_labels(self, msg) -> None:
        self.labels = list(msg.labels)

    def __call__(self, msg) -> None:
        labels = self.labels or [f"input {i}" for i in range(len(msg.spikes))]
        if labels != self.shown:
            self.shown = labels
            self.out.write("# one row per tick: '#' = the input spiked, '.' = it did not\n")
            for i, label in enumerate(labels):
                self.out.write(f"#   {i:2d} {label}\n")
            self.out.write("#" + " " * 25 + "|" + "".join(str(i % 10) for i in
                                                         range(len(labels))) + "|\n")
        row = "".join("#" if s else "." for s in msg.spikes)
        self.out.write(f"tick {msg.tick:9d} trial {msg.trial:4d} |{row}|\n")


def topic_type(node, topic: str, wait_s: float) -> str:
    """The graph's topics in any namespace are known without discovery, which can take seconds
    on a loaded machine; any other topic must be discovered within wait_s."""
    import rclpy
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.validate_topic_name import validate_topic_name
    try:
        validate_topic_name(topic)
    except InvalidTopicNameException as error:
        why = str(error).splitlines()[0].removeprefix("Invalid topic name: ").rstrip(":")
        raise EchoError(f"'{topic}' is not a topic name: {why}") from None
    resolved = node.resolve_topic_name(topic)
    if graph_topic(resolved) in TOPIC_TYPES:
        return TOPIC_TYPES[graph_topic(resolved)]
    deadline = time.monotonic() + wait_s
    while True:
        known = dict(node.get_topic_names_and_types())
        if resolved in known:
            return known[resolved][0]
        if time.monotonic() > deadline:
            names = sorted(set(known) | {absolute(name) for name in TOPIC_TYPES})
            raise EchoError(f"unknown topic '{topic}' (not published within {wait_s:g} s; "
                            f"topics: {', '.join(names)})")
        rclpy.spin_once(node, timeout_sec=0.05)


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.live.echo", name="echo",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("topic")
    parser.add_argument("--once", action="store_true", help="print one message and exit")
    parser.add_argument("--field", help="print only this field, e.g. tick, values or "
                                        "'values[2]' (an element by its index)")
    style = parser.add_mutually_exclusive_group()
    style.add_argument("--flow-style", action="store_true",
                       help="YAML with collections inline: {sec: 0, nanosec: 20000000}")
    style.add_argument("--csv", action="store_true",
                       help="one line per message: every field, comma-separated (for plotting)")
    style.add_argument("--raster", action="store_true",
                       help="/rln/spikes as one row per tick: tick T trial N |..#...|")
    parser.add_argument("--wait", type=float, default=3.0,
                        help="seconds to wait for a topic that is not one of the graph's (3)")
    args = parser.parse_args(argv)
    if args.raster and args.field:
        parser.error("--raster prints whole SpikeVectors: not with --field")
    import rclpy  # after the arguments: --help and a usage error need no ROS
    from ..session.rclpy_session import exit_keeping_participant, ros_session
    with ros_session() as received:
        node = rclpy.create_node("echo", start_parameter_services=False, enable_rosout=False)
        exit_keeping_participant(node, echo(node, args, received))


def echo(node, args, received: list[int]) -> int:
    """Print the topic's messages as asked; returns the exit status."""
    import rclpy
    from ..session.rclpy_session import qos_profile
    try:
        type_name = topic_type(node, args.topic, args.wait)
        cls = message_class(type_name)
        if args.raster and type_name != TOPIC_TYPES[SPIKES]:
            raise EchoError(f"--raster needs a SpikeVector topic such as /rln/spikes, not "
                            f"{args.topic} ({type_name})")
        if args.field:
            get_field(cls(), args.field, indexed=False)  # the names, before any message
        printed = []
        raster = Raster(sys.stdout) if args.raster else None

        def show(msg) -> None:
            if args.once and printed:
                return
            if raster is not None:
                raster(msg)
            else:
                value = get_field(msg, args.field) if args.field else msg
                sys.stdout.write(to_csv(value) + "\n" if args.csv else
                                 to_yaml(value, args.flow_style) + "---\n")
            sys.stdout.flush()
            printed.append(1)

        resolved = node.resolve_topic_name(args.topic)
        latched = graph_topic(resolved) in LATCHED  # published once: ask for the last
        node.create_subscription(cls, args.topic, show,
                                 qos_profile(qos.LABELS if latched else qos.ECHO))
        if raster is not None and graph_topic(resolved) == SPIKES:
            node.create_subscription(message_class(TOPIC_TYPES[INPUT_LABELS]),
                                     resolved.removesuffix(SPIKES) + INPUT_LABELS,
                                     raster.set_labels, qos_profile(qos.LABELS))
        while not received and not (args.once and printed):
            rclpy.spin_once(node, timeout_sec=0.1)
        return 128 + received[0] if received else 0
    except EchoError as error:
        print(f"echo: error: {error}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # `| head`
        sys.stderr.close()
        return 0
    except (ImportError, AttributeError, ValueError) as error:
        print(f"echo: error: cannot load the type of {args.topic}: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
