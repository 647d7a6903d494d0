"""Reading a bag: its MCAP file, opened whole or salvaged up to its last complete chunk, its
messages raw in file order, and their decoding with the schemas the bag holds."""

from __future__ import annotations

import struct
from pathlib import Path

import yaml

from ..graph.fields import stamp_nanoseconds
from ..graph.names import OLDER_STATE, graph_topic
from .directory import METADATA_FILE

MCAP_MAGIC = b"\x89MCAP0\r\n"


class BagError(Exception):
    """A bag that cannot be read (missing, not MCAP, truncated, not one of ours): one line."""


def relative_topic(resolved: str) -> str:
    """The graph's relative name of a recorded channel's topic in any namespace (names.graph_topic);
    the state channel of a bag recorded before contract version 4 ("/robot1/cartpole/state") by
    its relative name too (names.OLDER_STATE), so that old bags read like new ones."""
    name = graph_topic(resolved)
    if name == resolved and resolved.endswith("/" + OLDER_STATE):
        return OLDER_STATE
    return name


def tick_of(cdr: bytes, tau_ns: int, stamped: bool = False) -> int:
    """The tick of a serialized message of the graph, without deserializing it: its first field
    (uint64 tick), or where its first field is a sim-time stamp (`stamped`: /clock, and the
    graph's messages in bags of before 2026-12-04, which began with a std_msgs/Header) that time
    over tau. -1 for a message too short to hold one."""
    if len(cdr) < 12:
        return -1
    little = cdr[1] & 1  # the CDR encapsulation: little- or big-endian
    if stamped:
        sec, nanosec = struct.unpack_from("<iI" if little else ">iI", cdr, 4)
        return stamp_nanoseconds(sec, nanosec) // tau_ns
    return struct.unpack_from("<Q" if little else ">Q", cdr, 4)[0]


def begins_with_a_stamp(schema) -> bool:
    """Whether the messages of a bag's schema begin with a builtin_interfaces/Time (tick_of's
    `stamped`): the first field of its .msg text is a Clock's or a Header."""
    fields = (line.split("#")[0].split() for line in schema.data.decode().splitlines())
    first = next((field for field in fields if len(field) == 2 and "=" not in field[1]), None)
    return first is not None and first[0] in ("builtin_interfaces/Time", "std_msgs/Header")


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
    """(schema, topic, log_time, cdr bytes, recorded topic name)
    of the bag's messages in file order, the graph's topics by their relative names (a run in a
    namespace reads as any other: "/robot1/clock" is "clock"; an old bag's state is
    "cartpole/state": relative_topic); a salvaged (truncated) file ends quietly at its last
    complete record."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader
    try:
        for schema, channel, message in reader.iter_messages(topics=topics,
                                                             log_time_order=False):
            yield (schema, relative_topic(channel.topic), message.log_time, message.data,
                   channel.topic)
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


def metadata(path, name: str) -> dict | None:
    """A finished bag's metadata record `name` (None if it has none)."""
    reader, stream = open_bag(path)
    with stream:
        return next((dict(record.metadata) for record in reader.iter_metadata()
                     if record.name == name), None)
