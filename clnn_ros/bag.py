"""The project's recordings: rosbag2-compatible MCAP files (profile ros2, ros2msg schemas, cdr).

What the recorder (clnn_ros.nodes.recorder) writes and what clnn_ros.analyze reads:
* one channel per topic of the graph, message encoding `cdr` (the bytes DDS carried, untouched);
* schemas `ros2msg`: the installed .msg text, then each dependency as
  "=" * 80 + "\\nMSG: pkg/Type\\n" + its .msg text (what rosbag2 writes);
* channel metadata `topic_type_hash` (RIHS01, from <prefix>/share/<pkg>/msg/<Type>.json) and
  `offered_qos_profiles` (rosbag2 version 9 YAML);
* log_time = receive time (wall clock, ns), publish_time = the message's sim time (header stamp);
* a `rosbag2` metadata record (serialized_metadata, as `ros2 bag info` reads it) and a
  `clnn_ros` metadata record with the run's parameters;
* zstd chunks of CHUNK_SIZE bytes (uncompressed), each flushed when full, so that a recorder
  killed with SIGKILL leaves a file whose complete chunks can be read (`open_bag(salvage=True)`).
"""

from __future__ import annotations

import importlib
import json
import os
import re
import struct
import sys
from pathlib import Path

import yaml

from .names import graph_topic

CHUNK_SIZE = 512 * 1024  # about 1,000 ticks of the graph per chunk
ROSBAG2_VERSION = 9      # the bag format of ROS 2 Jazzy
PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
              "int32", "uint32", "int64", "uint64", "string", "wstring"}
SEPARATOR = "=" * 80


class BagError(Exception):
    """A bag that cannot be read (missing, not MCAP, truncated, not one of ours): one line."""


def message_class(type_name: str):
    """'pkg/msg/Type' -> the installed Python message class."""
    pkg, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def _prefixes() -> list[str]:
    found = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return found + [sys.prefix] if sys.prefix not in found else found


def _share_file(pkg: str, name: str, suffix: str) -> Path:
    for prefix in _prefixes():
        path = Path(prefix, "share", pkg, "msg", name + suffix)
        if path.is_file():
            return path
    raise FileNotFoundError(f"{pkg}/msg/{name}{suffix} is not installed under {_prefixes()}")


def _dependencies(pkg: str, text: str) -> list[tuple[str, str]]:
    found = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        base = re.sub(r"<=\d+$", "", re.sub(r"\[.*\]$", "", line.split()[0]))
        if base in PRIMITIVES:
            continue
        if base == "Header":
            found.append(("std_msgs", "Header"))
        elif "/" in base:
            parts = base.split("/")
            found.append((parts[0], parts[-1]))
        else:
            found.append((pkg, base))
    return found


def schema_text(type_name: str) -> str:
    """The ros2msg schema rosbag2 writes: the .msg text, then every dependency (depth first)."""
    pkg, _, name = type_name.split("/")
    main = _share_file(pkg, name, ".msg").read_text()
    seen, order = {(pkg, name)}, []
    stack = list(reversed(_dependencies(pkg, main)))
    while stack:
        dep = stack.pop()
        if dep in seen:
            continue
        seen.add(dep)
        order.append(dep)
        stack.extend(reversed(_dependencies(dep[0], _share_file(*dep, ".msg").read_text())))
    parts = [main.rstrip("\n")]
    for dep_pkg, dep_name in order:
        parts.append(f"{SEPARATOR}\nMSG: {dep_pkg}/{dep_name}\n"
                     + _share_file(dep_pkg, dep_name, ".msg").read_text().rstrip("\n"))
    return "\n".join(parts) + "\n"


def type_hash(type_name: str) -> str:
    """RIHS01 hash of the type, from the installed <Type>.json (rosbag2's topic_type_hash)."""
    pkg, _, name = type_name.split("/")
    for entry in json.loads(_share_file(pkg, name, ".json").read_text())["type_hashes"]:
        if entry["type_name"] == type_name:
            return entry["hash_string"]
    raise KeyError(f"no type hash for {type_name}")


def _duration(duration) -> dict:
    sec, nsec = divmod(int(duration.nanoseconds), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def qos_dicts(profiles) -> list[dict]:
    """rclpy QoSProfiles -> rosbag2 (version 9) offered_qos_profiles entries."""
    return [{
        "history": q.history.name.lower(), "depth": int(q.depth),
        "reliability": q.reliability.name.lower(), "durability": q.durability.name.lower(),
        "deadline": _duration(q.deadline), "lifespan": _duration(q.lifespan),
        "liveliness": q.liveliness.name.lower(),
        "liveliness_lease_duration": _duration(q.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": bool(q.avoid_ros_namespace_conventions),
    } for q in profiles]


def qos_yaml(profiles) -> str:
    return yaml.safe_dump(qos_dicts(profiles), default_flow_style=False, sort_keys=False).strip() \
        if profiles else ""


def stamp_ns(cdr: bytes) -> int:
    """Sim time of a serialized message whose first field is a builtin_interfaces/Time (every
    message of the graph: the Header's stamp, or Clock.clock), without deserializing it."""
    if len(cdr) < 12:
        return 0
    sec, nanosec = struct.unpack_from("<iI" if cdr[1] & 1 else ">iI", cdr, 4)
    return sec * 1_000_000_000 + nanosec


def rosbag2_metadata(path: Path, topics: list[dict], counts: dict, start_ns: int,
                     end_ns: int) -> str:
    """The YAML rosbag2 keeps in the MCAP `rosbag2` metadata record (serialized_metadata)."""
    total = sum(counts.values())
    duration = max(0, end_ns - start_ns)
    return yaml.safe_dump({
        "version": ROSBAG2_VERSION, "storage_identifier": "mcap",
        "relative_file_paths": [path.name],
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start_ns},
        "message_count": total,
        "topics_with_message_count": [{
            "topic_metadata": {"name": t["name"], "type": t["type"],
                               "serialization_format": "cdr",
                               "offered_qos_profiles": t["qos"],
                               "type_description_hash": t["hash"]},
            "message_count": counts.get(t.get("topic", t["name"]), 0)} for t in topics],
        "compression_format": "", "compression_mode": "",
        "files": [{"path": path.name, "starting_time": {"nanoseconds_since_epoch": start_ns},
                   "duration": {"nanoseconds": duration}, "message_count": total}],
        "custom_data": None, "ros_distro": "jazzy",
    }, default_flow_style=False, sort_keys=False).strip()


# ---------------------------------------------------------------------------------------------
# Reading


def open_bag(path, salvage: bool = False):
    """Check that `path` is a complete MCAP recording and return (reader, stream).
    A truncated file (no footer/summary: the recorder was killed) is refused unless `salvage`,
    which reads it linearly up to the last complete record."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader, SeekingReader

    path = Path(path)
    if not path.is_file():
        raise BagError(f"{path}: no such file")
    stream = open(path, "rb")
    try:
        if stream.read(8) != b"\x89MCAP0\r\n":
            raise BagError(f"{path}: not an MCAP file")
        stream.seek(0)
        try:
            reader = SeekingReader(stream)
            summary = reader.get_summary()
            if summary is None or not summary.chunk_indexes and summary.statistics is None:
                raise McapError("no summary")
            return reader, stream
        except (McapError, EOFError, ValueError, struct.error, OSError, StopIteration):
            if not salvage:
                raise BagError(f"{path}: truncated or damaged MCAP (no readable summary at "
                               f"its end: was the recorder killed?); --salvage reads its "
                               f"complete chunks") from None
        stream.seek(0)
        return NonSeekingReader(stream), stream
    except BaseException:
        stream.close()
        raise


def iter_raw(reader, topics=None):
    """(schema, topic, publish_time, log_time, cdr bytes, recorded topic name) of the bag's
    messages in file order, the graph's topics by their relative names (a run in a namespace
    reads as any other: "/robot1/clock" is "clock"); a
    salvaged (truncated) file ends quietly at its last complete record."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader
    try:
        for schema, channel, message in reader.iter_messages(topics=topics,
                                                             log_time_order=False):
            yield (schema, graph_topic(channel.topic), message.publish_time, message.log_time,
                   message.data, channel.topic)
    except (McapError, EOFError, struct.error, ValueError) as error:
        if not isinstance(reader, NonSeekingReader):
            raise BagError(f"damaged MCAP: {error}") from None


class Decoder:
    """Decodes CDR with the schema embedded in the bag (mcap_ros2), not the installed types."""

    def __init__(self):
        from mcap_ros2.decoder import DecoderFactory
        self.factory = DecoderFactory()
        self.decoders = {}

    def __call__(self, schema, cdr: bytes):
        decoder = self.decoders.get(schema.id)
        if decoder is None:
            decoder = self.decoders[schema.id] = self.factory.decoder_for("cdr", schema)
        return decoder(cdr)

