"""Writing a bag: BagWriter and the rosbag2 metadata it writes (the offered QoS, metadata.yaml
as yaml-cpp emits it)."""

from __future__ import annotations

import time
from pathlib import Path

import yaml

from ..files import write_text_atomically
from .directory import METADATA_FILE, bag_files, remove_bag

CHUNK_SECONDS = 0.5        # a chunk is closed this long after its first message (wall clock)
CHUNK_BYTES = 1024 * 1024  # or once it holds this much (uncompressed): a bound on memory
MESSAGE_RECORD_BYTES = 31  # an MCAP Message record without its data
ROSBAG2_VERSION = 9        # the bag format of ROS 2 Jazzy
ROS_DISTRO = "jazzy"
INT64_MAX = 2**63 - 1      # rosbag2's starting_time of a bag without messages


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


class BagWriter:
    """One bag directory as rosbag2's writer with the mcap storage plugin makes it (clnn_ros.bag's
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


def note_in_metadata(directory: Path, notes: dict[str, str]) -> None:
    """Add `notes` to a finished bag's metadata.yaml as rosbag2's `custom_data` (a map of strings
    that `ros2 bag info` and bag readers keep): what was learnt only after the bag was closed."""
    path = Path(directory) / METADATA_FILE
    document = yaml.safe_load(path.read_text())
    information = document["rosbag2_bagfile_information"]
    information["custom_data"] = {**(information.get("custom_data") or {}),
                                  **{str(k): str(v) for k, v in notes.items()}}
    write_text_atomically(path, dump_yaml(document) + "\n")


def metadata_notes(directory: Path) -> dict[str, str]:
    """A bag's metadata.yaml `custom_data` ({} where it has none or no readable metadata.yaml)."""
    try:
        document = yaml.safe_load((Path(directory) / METADATA_FILE).read_text())
        return dict(document["rosbag2_bagfile_information"].get("custom_data") or {})
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError):
        return {}
