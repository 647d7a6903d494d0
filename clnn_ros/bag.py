"""The project's recordings: rosbag2 bag directories as `ros2 bag record -s mcap -o NAME` (ROS 2
Jazzy) writes them, and the tools that read and repair them.

    python -m clnn_ros.bag repair BROKEN [--out FIXED]   # a killed recorder's bag, finalized

A bag is a directory NAME/ with NAME/metadata.yaml (rosbag2_bagfile_information, version 9) and
one MCAP file NAME/NAME_0.mcap (profile ros2):
* one channel per topic of the graph, message encoding `cdr` (the bytes DDS carried, untouched);
* schemas `ros2msg`: the installed .msg text, then each dependency as
  "=" * 80 + "\\nMSG: pkg/Type\\n" + its .msg text (what rosbag2 writes);
* channel metadata `topic_type_hash` (RIHS01, from <prefix>/share/<pkg>/msg/<Type>.json) and
  `offered_qos_profiles` (the publishers' QoS, a YAML list as version 9 has it);
* log_time = the receive time and publish_time = the publisher's source timestamp (both wall
  clock, ns, from DDS, as Jazzy's recorder sets them); the sim time is in each message's header;
* `rosbag2` metadata records (serialized_metadata: one when the bag opens, the final one when it
  is closed, as rosbag2's writer does) and a `clnn_ros` record with the run's parameters;
* zstd chunks closed every CHUNK_SECONDS (or CHUNK_BYTES) and written through to the file, so a
  recorder killed with SIGKILL loses at most the open chunk: `repair` makes a finalized copy of
  the complete ones, `open_bag(salvage=True)` reads them as they are.
"""

from __future__ import annotations

import importlib
import json
import os
import re
import struct
import sys
import time
from pathlib import Path

import yaml

from .files import describe_write_error, write_text_atomically
from .names import graph_topic

CHUNK_SECONDS = 0.5        # a chunk is closed this long after its first message (wall clock)
CHUNK_BYTES = 1024 * 1024  # or once it holds this much (uncompressed): a bound on memory
MESSAGE_RECORD_BYTES = 31  # an MCAP Message record without its data
ROSBAG2_VERSION = 9        # the bag format of ROS 2 Jazzy
ROS_DISTRO = "jazzy"
METADATA_FILE = "metadata.yaml"
INT64_MAX = 2**63 - 1      # rosbag2's starting_time of a bag without messages
PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
              "int32", "uint32", "int64", "uint64", "string", "wstring"}
SEPARATOR = "=" * 80
MCAP_MAGIC = b"\x89MCAP0\r\n"


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


class _YamlCppDumper(yaml.SafeDumper):
    """YAML as yaml-cpp (rosbag2) emits it: block sequences indented under their key, `~` for
    null, `""` for an empty string."""

    def increase_indent(self, flow=False, indentless=False):
        return super().increase_indent(flow, False)

    def ignore_aliases(self, data):
        return True


_YamlCppDumper.add_representer(type(None), lambda dumper, _: dumper.represent_scalar(
    "tag:yaml.org,2002:null", "~"))
_YamlCppDumper.add_representer(str, lambda dumper, text: dumper.represent_scalar(
    "tag:yaml.org,2002:str", text, style='"' if text == "" else None))


def dump_yaml(data) -> str:
    return yaml.dump(data, Dumper=_YamlCppDumper, default_flow_style=False, sort_keys=False,
                     width=2**31).rstrip("\n")


def stamp_ns(cdr: bytes) -> int:
    """Sim time of a serialized message whose first field is a builtin_interfaces/Time (every
    message of the graph: the Header's stamp, or Clock.clock), without deserializing it."""
    if len(cdr) < 12:
        return 0
    sec, nanosec = struct.unpack_from("<iI" if cdr[1] & 1 else ">iI", cdr, 4)
    return sec * 1_000_000_000 + nanosec


def bag_files(directory: Path) -> tuple[str, str]:
    """The names of the files this project writes in a bag directory: metadata.yaml, NAME_0.mcap."""
    return METADATA_FILE, f"{Path(directory).name}_0.mcap"


def foreign_files(directory: Path) -> list[str]:
    """What a directory holds besides a bag's own files (a bag is replaced, nothing else)."""
    return sorted(p.name for p in Path(directory).iterdir() if p.name not in bag_files(directory))


def remove_bag(directory: Path) -> None:
    """Remove a bag's own files, then the directory if that left it empty."""
    for name in bag_files(directory):
        (Path(directory) / name).unlink(missing_ok=True)
    try:
        Path(directory).rmdir()
    except OSError:  # missing, or it holds something else
        pass


class BagWriter:
    """One bag directory as rosbag2's writer with the mcap storage plugin makes it (module
    docstring). Chunks are closed here, never by the mcap writer itself (that would leave them in
    the file's buffer): after `chunk_seconds` (checked as messages come and by `flush_if_due`) or
    CHUNK_BYTES. An earlier bag of the same directory is replaced. OSError (a full disk) is
    raised to the caller."""

    def __init__(self, directory: Path, library: str, chunk_seconds: float | None = CHUNK_SECONDS):
        from mcap.writer import CompressionType, Writer
        self.directory = Path(directory)
        remove_bag(self.directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.path = self.directory / bag_files(self.directory)[1]
        self.file = open(self.path, "wb")
        self.writer = Writer(self.file, chunk_size=2 * CHUNK_BYTES,
                             compression=CompressionType.ZSTD)
        self.writer.start(profile="ros2", library=library)
        self.chunk_seconds = chunk_seconds
        self.chunk_bytes = 0
        self.chunk_opened = None  # time.monotonic() of the open chunk's first message
        self.schemas = {}         # type name -> schema id
        self.topics = {}          # channel id -> rosbag2 topic metadata and its message count
        self.first_ns = self.last_ns = None
        self.closed = False
        self.add_metadata("rosbag2", {"serialized_metadata": dump_yaml(self.metadata())})

    def add_metadata(self, name: str, data: dict) -> None:
        """A metadata record, on disk at once."""
        self.writer.add_metadata(name, data)
        self.close_chunk()

    def add_topic(self, name: str, type_name: str, schema: str, qos: list[dict],
                  type_description_hash: str) -> int:
        """A channel (and its type's schema, once); returns the channel id."""
        schema_id = self.schemas.get(type_name)
        if schema_id is None:
            schema_id = self.schemas[type_name] = self.writer.register_schema(
                name=type_name, encoding="ros2msg", data=schema.encode())
        channel = self.writer.register_channel(
            topic=name, message_encoding="cdr", schema_id=schema_id,
            metadata={"offered_qos_profiles": dump_yaml(qos),
                      "topic_type_hash": type_description_hash})
        self.topics[channel] = {"name": name, "type": type_name, "qos": qos,
                                "hash": type_description_hash, "count": 0}
        return channel

    def write(self, channel: int, log_ns: int, publish_ns: int, data: bytes,
              sequence: int) -> None:
        self.writer.add_message(channel_id=channel, log_time=log_ns, data=data,
                                publish_time=publish_ns, sequence=sequence)
        self.topics[channel]["count"] += 1
        self.first_ns = log_ns if self.first_ns is None else min(self.first_ns, log_ns)
        self.last_ns = log_ns if self.last_ns is None else max(self.last_ns, log_ns)
        self.chunk_bytes += MESSAGE_RECORD_BYTES + len(data)
        if self.chunk_opened is None:
            self.chunk_opened = time.monotonic()
        if self.chunk_bytes >= CHUNK_BYTES:
            self.close_chunk()
        else:
            self.flush_if_due()

    def flush_if_due(self) -> None:
        if self.chunk_opened is not None and self.chunk_seconds is not None and \
                time.monotonic() - self.chunk_opened >= self.chunk_seconds:
            self.close_chunk()

    def close_chunk(self) -> None:
        """The open chunk, compressed, into the file (past Python's buffer: a SIGKILL from now on
        loses only later messages)."""
        self.writer.flush()
        self.chunk_bytes, self.chunk_opened = 0, None

    @property
    def message_count(self) -> int:
        return sum(topic["count"] for topic in self.topics.values())

    def metadata(self) -> dict:
        """rosbag2's BagMetadata (version 9) of what was written so far, keys in Jazzy's order."""
        start = INT64_MAX if self.first_ns is None else self.first_ns
        duration = {"nanoseconds": 0 if self.first_ns is None else self.last_ns - self.first_ns}
        count = self.message_count
        return {
            "version": ROSBAG2_VERSION, "storage_identifier": "mcap", "duration": duration,
            "starting_time": {"nanoseconds_since_epoch": start}, "message_count": count,
            "topics_with_message_count": [{
                "topic_metadata": {"name": t["name"], "type": t["type"],
                                   "serialization_format": "cdr", "offered_qos_profiles": t["qos"],
                                   "type_description_hash": t["hash"]},
                "message_count": t["count"]} for t in self.topics.values()],
            "compression_format": "", "compression_mode": "",
            "relative_file_paths": [self.path.name],
            "files": [{"path": self.path.name, "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": duration, "message_count": count}],
            "custom_data": None, "ros_distro": ROS_DISTRO,
        }

    def close(self, finalize: bool = True) -> None:
        """Finalize (the last `rosbag2` record, summary and index, then metadata.yaml) or, after a
        failed write, only close the file (idempotent)."""
        if self.closed:
            return
        self.closed = True
        try:
            if finalize:
                self.writer.add_metadata("rosbag2",
                                         {"serialized_metadata": dump_yaml(self.metadata())})
                self.writer.finish()
        finally:
            try:
                self.file.close()
            except OSError:
                if finalize:
                    raise
        if finalize:
            write_text_atomically(self.directory / METADATA_FILE, dump_yaml(
                {"rosbag2_bagfile_information": self.metadata()}) + "\n")


# ---------------------------------------------------------------------------------------------
# Reading


def mcap_file(path) -> Path:
    """The MCAP file of a bag: that of a bag directory (the file its metadata.yaml names, else
    its only .mcap) or an .mcap file itself. BagError (one line) if there is none."""
    path = Path(path)
    if path.is_dir():
        metadata = path / METADATA_FILE
        if metadata.is_file():
            try:
                files = yaml.safe_load(metadata.read_text())["rosbag2_bagfile_information"][
                    "relative_file_paths"]
                files = [str(name) for name in files]
            except (OSError, UnicodeError, yaml.YAMLError, KeyError, TypeError) as error:
                raise BagError(f"{metadata}: not a rosbag2 metadata file "
                               f"({type(error).__name__})") from None
            if len(files) != 1:
                raise BagError(f"{path}: a bag of {len(files)} files (split): not supported")
            if not (path / files[0]).is_file():
                raise BagError(f"{path / files[0]}: no such file (named in {metadata})")
            return path / files[0]
        found = sorted(path.glob("*.mcap"))
        if len(found) != 1:
            raise BagError(f"{path}: no .mcap file in the directory" if not found else
                           f"{path}: {len(found)} .mcap files and no {METADATA_FILE}")
        return found[0]
    if not path.is_file():
        raise BagError(f"{path}: no such file or directory")
    return path


def check_magic(stream, path: Path) -> None:
    """BagError unless the stream starts as an MCAP file does; it is left at its start."""
    if stream.read(8) != MCAP_MAGIC:
        raise BagError(f"{path}: not an MCAP file")
    stream.seek(0)


def open_bag(path, salvage: bool = False):
    """Check that `path` (a bag directory or .mcap file) is a complete MCAP recording and return
    (reader, stream). A truncated file (no footer/summary: the recorder was killed) is refused
    unless `salvage`, which reads it linearly up to the last complete record."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader, SeekingReader

    path = mcap_file(path)
    stream = open(path, "rb")
    try:
        check_magic(stream, path)
        try:
            reader = SeekingReader(stream)
            summary = reader.get_summary()
            if summary is None or not summary.chunk_indexes and summary.statistics is None:
                raise McapError("no summary")
            return reader, stream
        except (McapError, EOFError, ValueError, struct.error, OSError, StopIteration):
            if not salvage:
                raise BagError(f"{path}: truncated or damaged MCAP (no readable summary at "
                               f"its end: was the recorder killed?); `python -m clnn_ros.bag "
                               f"repair` makes a finished copy, --salvage reads its complete "
                               f"chunks") from None
        stream.seek(0)
        return NonSeekingReader(stream), stream
    except BaseException:
        stream.close()
        raise


def iter_raw(reader, topics=None):
    """(schema, topic, sim time (ns: the header stamp), log_time, cdr bytes, recorded topic name)
    of the bag's messages in file order, the graph's topics by their relative names (a run in a
    namespace reads as any other: "/robot1/clock" is "clock"); a salvaged (truncated) file ends
    quietly at its last complete record."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader
    try:
        for schema, channel, message in reader.iter_messages(topics=topics,
                                                             log_time_order=False):
            yield (schema, graph_topic(channel.topic), stamp_ns(message.data), message.log_time,
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


# ---------------------------------------------------------------------------------------------
# Repair


def repaired_path(source: Path) -> Path:
    """SOURCE_repaired beside a bag directory, or beside an .mcap file (without .mcap)."""
    source = Path(source)
    base = source if source.is_dir() else source.with_suffix("")
    return base.with_name(base.name + "_repaired")


def repair(source, out=None) -> tuple[Path, int, bool]:
    """A finalized, indexed copy of a bag whose recorder was killed, as a new bag directory `out`
    (default: repaired_path): every message of its complete chunks, with its schemas, channels
    and metadata records (`rosbag2` written anew). Returns (out, messages, whether the source was
    already complete). BagError for a source that is none or holds no complete chunk."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Footer, Header, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    source_file = mcap_file(source)
    out = Path(out) if out is not None else repaired_path(Path(source))
    if out.exists():
        raise BagError(f"{out} exists: give another --out")
    with open(source_file, "rb") as stream:
        check_magic(stream, source_file)
        writer, complete = None, False
        schemas, channels = {}, {}  # the source's ids -> its schema records, the copy's channels
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Header):
                    writer = BagWriter(out, f"{record.library} (repaired by clnn_ros.bag)",
                                       chunk_seconds=None)
                elif isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel) and record.id not in channels:
                    schema = schemas[record.schema_id]
                    channels[record.id] = writer.add_topic(
                        record.topic, schema.name, schema.data.decode(),
                        yaml.safe_load(record.metadata.get("offered_qos_profiles") or "[]") or [],
                        record.metadata.get("topic_type_hash", ""))
                elif isinstance(record, Message):
                    writer.write(channels[record.channel_id], record.log_time,
                                 record.publish_time, record.data, record.sequence)
                elif isinstance(record, Metadata) and record.name != "rosbag2":
                    writer.add_metadata(record.name, record.metadata)
                elif isinstance(record, Footer):
                    complete = True
        except (McapError, EOFError, struct.error, ValueError, KeyError):
            pass  # the end of what was written: an unfinished chunk or record
        except BaseException:
            if writer is not None:
                writer.close(finalize=False)
                remove_bag(out)
            raise
    if writer is None or not writer.message_count:
        if writer is not None:
            writer.close(finalize=False)
            remove_bag(out)
        raise BagError(f"{source_file}: no complete chunk (nothing was recorded to keep)")
    writer.close()
    return out, writer.message_count, complete


def main(argv=None) -> int:
    from .cli import OneLineArgumentParser
    parser = OneLineArgumentParser(prog="python -m clnn_ros.bag", name="bag",
                                   description="Tools for the project's bags.")
    commands = parser.add_subparsers(dest="command", required=True)
    repair_command = commands.add_parser(
        "repair", help="a finalized copy of a bag whose recorder was killed",
        description="Write a finalized, indexed copy (a new bag directory with metadata.yaml) of "
                    "a bag whose recorder was killed: every message of its complete chunks.")
    repair_command.add_argument("bag", type=Path, help="the bag directory, or its .mcap file")
    repair_command.add_argument("--out", type=Path,
                                help="the new bag directory (default: <bag>_repaired)")
    args = parser.parse_args(argv)
    try:
        out, messages, complete = repair(args.bag, args.out)
    except BagError as error:
        print(f"bag: error: {error}", file=sys.stderr)
        return 1
    except OSError as error:
        print(f"bag: error: {describe_write_error(error)}", file=sys.stderr)
        return 1
    print(f"bag: {messages} messages" + (f" ({args.bag} was complete)" if complete else
                                         " (every complete chunk)") + f" in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
