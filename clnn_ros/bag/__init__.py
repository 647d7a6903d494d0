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
  clock, ns, from DDS, as Jazzy's recorder sets them); each message's sim time is its tick * tau
  (its first field, read by `tick_of`), /clock's its stamp;
* `rosbag2` metadata records (serialized_metadata: one when the bag opens, the final one when it
  is closed, as rosbag2's writer does) and a `clnn_ros` record with the run's parameters;
* metadata.yaml's `custom_data`: run_all's notes of how far the run went, added once it ended;
* zstd chunks closed every CHUNK_SECONDS (or CHUNK_BYTES) and written through to the file, so a
  recorder killed with SIGKILL loses at most the open chunk: `repair` makes a finalized copy of
  the complete ones, `open_bag(salvage=True)` reads them as they are.

    directory  a bag directory's own files
    schemas    the installed message types: class, ros2msg schema, type hash
    writer     BagWriter and the metadata it writes; notes added to metadata.yaml later
    reader     open_bag, iter_raw, Decoder
    repair     a finalized copy of a killed recorder's bag

No ROS import (mcap is loaded when a bag is written or read): offline tools read bags without
rclpy. The names below are those the recorder, run_all, echo and analyze use.
"""

from .directory import METADATA_FILE, foreign_files, remove_bag
from .reader import (BagError, Decoder, begins_with_a_stamp, iter_raw, mcap_file, metadata,
                     open_bag, relative_topic, tick_of)
from .schemas import message_class, schema_text, type_hash
from .writer import CHUNK_SECONDS, BagWriter, metadata_notes, note_in_metadata, qos_dicts

__all__ = ["METADATA_FILE", "foreign_files", "remove_bag", "BagError", "Decoder",
           "begins_with_a_stamp", "iter_raw", "mcap_file", "metadata", "open_bag",
           "relative_topic", "tick_of",
           "message_class", "schema_text", "type_hash", "CHUNK_SECONDS", "BagWriter",
           "metadata_notes", "note_in_metadata", "qos_dicts"]
