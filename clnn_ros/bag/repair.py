"""A finalized copy of a bag whose recorder was killed: every message of its complete chunks
(`python -m clnn_ros.bag repair`)."""

from __future__ import annotations

import contextlib
import struct
from pathlib import Path

import yaml

from .directory import remove_bag
from .reader import BagError, check_magic, mcap_file
from .writer import BagWriter


def repaired_path(source: Path) -> Path:
    """SOURCE_repaired beside a bag directory, or beside an .mcap file (without .mcap)."""
    source = Path(source)
    base = source if source.is_dir() else source.with_suffix("")
    return base.with_name(base.name + "_repaired")


def repair(source, out=None) -> tuple[Path, int, bool]:
    """A finalized, indexed copy of a bag whose recorder was killed, as a new bag directory `out`
    (default: repaired_path): every message of its complete chunks, with its schemas, channels
    and metadata records (`rosbag2` written anew). Returns (out, messages, whether the source was
    already complete). BagError for a source that is none or holds no complete chunk; OSError
    (a full disk) leaves no half-written copy."""
    source_file = mcap_file(source)
    out = Path(out) if out is not None else repaired_path(Path(source))
    if out.exists():
        raise BagError(f"{out} exists: give another --out")
    with open(source_file, "rb") as stream:
        check_magic(stream, source_file)
        writer, complete = copy_complete_chunks(stream, out)
    try:
        if writer is None or not writer.message_count:
            raise BagError(f"{source_file}: no complete chunk (nothing was recorded to keep)")
        writer.close()
    except BaseException:
        discard(writer, out)
        raise
    return out, writer.message_count, complete


def copy_complete_chunks(stream, out: Path) -> tuple[BagWriter | None, bool]:
    """(the copy's BagWriter, still open, or None; whether the source was complete): every
    message of the source's complete chunks, with its schemas, channels and metadata records."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Footer, Header, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

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
    except BaseException:  # a full disk too
        discard(writer, out)
        raise
    return writer, complete


def discard(writer: BagWriter | None, out: Path) -> None:
    """Remove a copy that could not be finished (its files may be what filled the disk)."""
    if writer is not None:
        with contextlib.suppress(OSError):
            writer.close(finalize=False)
    remove_bag(out)
