"""Print the live messages of a topic as YAML, in the layout of `ros2 topic echo` (no ROS CLI
is needed: rclpy only). Run it against a graph started in another terminal (same ROS_DOMAIN_ID).

    python -m clnn_ros.echo /cartpole/state
    python -m clnn_ros.echo /rln/action --once
    python -m clnn_ros.echo /cartpole/state --field pole_angle_deg
    python -m clnn_ros.echo /rln/spikes --raster      # one row per tick: tick 12 trial 0 |....#.|

Messages are separated by `---`; arrays of numbers or strings are printed inline ([0, 1, 0]).
The graph's topics are known in advance (echo may start before the graph); any other topic
must be published within --wait seconds. Exit status: 0 after --once, 130 on Ctrl-C, 1 for an
unknown topic or field.
"""

from __future__ import annotations

import array
import sys
import time

from . import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)

import yaml

from . import qos
from .bag import message_class
from .cli import OneLineArgumentParser
from .names import TOPIC_TYPES, absolute, graph_topic


class EchoError(Exception):
    pass


def _scalar(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    text = yaml.safe_dump(value, default_flow_style=True, width=10**9).strip()
    return text[:-4].strip() if text.endswith("\n...") else text.removesuffix("...").strip()


def _inline(values) -> str:
    """A list of scalars in YAML flow style, strings quoted where YAML needs it."""
    return yaml.safe_dump([_plain(v) for v in values], default_flow_style=True,
                          width=10**9).strip()


def _is_message(value) -> bool:
    return hasattr(value, "get_fields_and_field_types")


def _plain(value):
    if isinstance(value, (bytes, bytearray, array.array)):
        return list(value)
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def to_yaml_lines(value, indent: int = 0) -> list[str]:
    """A message as `ros2 topic echo` prints it: fields in declaration order, nested messages
    indented by two spaces, arrays of scalars inline."""
    pad = " " * indent
    lines = []
    for name in value.get_fields_and_field_types():
        field = _plain(getattr(value, name))
        if _is_message(field):
            lines.append(f"{pad}{name}:")
            lines += to_yaml_lines(field, indent + 2)
        elif isinstance(field, (list, tuple)):
            if field and _is_message(field[0]):
                lines.append(f"{pad}{name}:")
                for item in field:
                    sub = to_yaml_lines(item, indent + 2)
                    sub[0] = f"{pad}- " + sub[0][indent + 2:]
                    lines += sub
            else:
                lines.append(f"{pad}{name}: {_inline(field)}")
        else:
            lines.append(f"{pad}{name}: {_scalar(field)}")
    return lines


def format_value(value) -> str:
    value = _plain(value)
    if _is_message(value):
        return "\n".join(to_yaml_lines(value))
    if isinstance(value, (list, tuple)):
        return _inline(value)
    return _scalar(value)


def get_field(msg, path: str):
    value = msg
    for part in path.split("."):
        if not _is_message(value) or part not in value.get_fields_and_field_types():
            known = ", ".join(value.get_fields_and_field_types()) if _is_message(value) else "none"
            raise EchoError(f"no field '{part}' in --field {path} (fields there: {known})")
        value = getattr(value, part)
    return value


class Raster:
    """/rln/spikes as one text row per tick; the input labels as a header once."""

    def __init__(self, out):
        self.out, self.labels = out, None

    def __call__(self, msg) -> None:
        labels = list(msg.input_labels)
        if labels != self.labels:
            self.labels = labels
            self.out.write("# one row per tick: '#' = the input spiked, '.' = it did not\n")
            for i, label in enumerate(labels):
                self.out.write(f"#   {i:2d} {label}\n")
            self.out.write("#" + " " * 25 + "|" + "".join(str(i % 10) for i in
                                                         range(len(labels))) + "|\n")
        row = "".join("#" if s else "." for s in _plain(msg.spikes))
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
    known_name = graph_topic(node.resolve_topic_name(topic))
    if known_name in TOPIC_TYPES:
        return TOPIC_TYPES[known_name]
    deadline = time.monotonic() + wait_s
    while True:
        known = dict(node.get_topic_names_and_types())
        if topic in known:
            return known[topic][0]
        if time.monotonic() > deadline:
            names = sorted(set(known) | {absolute(name) for name in TOPIC_TYPES})
            raise EchoError(f"unknown topic '{topic}' (not published within {wait_s:g} s; "
                            f"topics: {', '.join(names)})")
        rclpy.spin_once(node, timeout_sec=0.05)


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.echo", name="echo",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("topic")
    parser.add_argument("--once", action="store_true", help="print one message and exit")
    parser.add_argument("--field", help="print only this field, e.g. header.stamp or pole_angle_deg")
    parser.add_argument("--raster", action="store_true",
                        help="/rln/spikes as one row per tick: tick T trial N |..#...|")
    parser.add_argument("--wait", type=float, default=3.0,
                        help="seconds to wait for a topic that is not one of the graph's (3)")
    args = parser.parse_args(argv)
    import rclpy  # after the arguments: --help and a usage error need no ROS
    from .nodes.common import qos_profile, ros_session
    with ros_session() as received:
        node = rclpy.create_node("echo", start_parameter_services=False, enable_rosout=False)
        try:
            type_name = topic_type(node, args.topic, args.wait)
            cls = message_class(type_name)
            if args.raster and not hasattr(cls(), "input_labels"):
                raise EchoError(f"--raster needs a SpikeVector topic such as /rln/spikes, not "
                                f"{args.topic} ({type_name})")
            if args.field:
                get_field(cls(), args.field)  # check the path before any message comes
            printed = []
            raster = Raster(sys.stdout) if args.raster else None

            def show(msg) -> None:
                if args.once and printed:
                    return
                if raster is not None:
                    raster(msg)
                else:
                    text = format_value(get_field(msg, args.field) if args.field else msg)
                    sys.stdout.write(text + "\n---\n")
                sys.stdout.flush()
                printed.append(1)

            node.create_subscription(cls, args.topic, show, qos_profile(qos.ECHO))
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
        finally:
            node.destroy_node()


if __name__ == "__main__":
    sys.exit(main())
