"""Recorder node: every topic of the graph into one rosbag2-compatible MCAP file (clnn_ros.bag).

    python -m clnn_ros.nodes.recorder --ros-args -p bag_path:=run.mcap [--params-file P]

It subscribes raw (the CDR bytes, never decoded) to /clock, /trial/event, /cartpole/state,
/rln/spikes, /rln/reward, /rln/action and /rln/weights with a deep reader queue, and announces
"recorder" on /graph/ready once each subscription sees its publisher; run_all makes the trial
manager wait for it (run setting extra_nodes), so the first tick is recorded. Every 20 ms it
publishes on /recorder/progress the last tick it holds on every per-tick topic; the trial manager
keeps the graph within RECORDER_WINDOW ticks of it, so a slow recorder loses nothing. The file is
finished (rosbag2 metadata, summary, index) on EPISODE_END (a normal end, or a stall the trial
manager detected), on Ctrl-C and on SIGTERM. Complete chunks are flushed as they fill, so a
SIGKILL loses at most the open chunk. Parameters from --params-file (the run's) are stored in
the bag's `clnn_ros` metadata record. Exit status 0, 130/143 after a signal, 2 if the bag
cannot be written.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from .. import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)
from ..rosenv import remove_unused_fast_dds_files

from mcap.writer import CompressionType, Writer
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rclpy.task import Future
from std_msgs.msg import String, UInt64

from clnn_ros_msgs.msg import TrialEvent

from .. import bag
from .common import (PROGRESS_QOS, READY, READY_QOS, RECORDED, TRIAL_EVENT,
                     Alive, ros_session, spin_until_finished)

NAME = "recorder"
PER_TICK = ("/clock", "/cartpole/state", "/rln/spikes", "/rln/reward", "/rln/action")
# Deep enough that the DDS receive thread never drops a message while Python is busy (the
# graph's publishers keep 2000): the recorder may lag behind the lockstep graph without loss.
RECORD_QOS = QoSProfile(depth=100_000, reliability=ReliabilityPolicy.RELIABLE,
                        history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
LINGER_S = 0.3      # after EPISODE_END: wait for messages still in flight on other topics
LINGER_MAX_S = 2.0


class RecorderNode(Node):
    def __init__(self, bag_path: str | None = None, context=None):
        super().__init__(NAME, context=context,
                         automatically_declare_parameters_from_overrides=True)
        if bag_path is None:
            bag_path = self.get_parameter("bag_path").value if self.has_parameter("bag_path") \
                else ""
        if not bag_path:
            raise ValueError("bag_path is not set (-p bag_path:=FILE.mcap)")
        self.path = Path(bag_path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.file = open(self.path, "wb")
        # Every index type, message indexes included (rosbags finds no message without them).
        self.writer = Writer(self.file, chunk_size=bag.CHUNK_SIZE,
                             compression=CompressionType.ZSTD)
        self.writer.start(profile="ros2", library="clnn_ros recorder")
        parameters = {name: p.value for name, p in self._parameters.items()
                      if name not in ("bag_path", "use_sim_time", "start_type_description_service")}
        self.writer.add_metadata("clnn_ros", {"parameters": json.dumps(parameters, sort_keys=True),
                                              "bag_format": "clnn_ros.bag"})
        self.channels = {}     # topic -> channel id
        self.topics = []       # rosbag2 topic metadata
        self.counts = {topic: 0 for topic in bag.TOPIC_TYPES}
        self.first_ns = self.last_ns = None
        self.last_tick = {}    # per-tick topic -> sim time of its last message
        self.missing = 0       # messages of per-tick topics that never arrived (gaps)
        self.subscriptions_by_topic = {}
        tau = self.get_parameter("tau").value if self.has_parameter("tau") else 0.02
        self.tau_ns = round(float(tau) * 1e9)
        for topic, type_name in bag.TOPIC_TYPES.items():
            self.subscriptions_by_topic[topic] = self.create_subscription(
                bag.message_class(type_name), topic, self._receiver(topic), RECORD_QOS, raw=True)
        self.finished = Future()
        self.episode_end_at = None
        self.last_message_at = time.monotonic()
        self._ready_publisher = self.create_publisher(String, READY, READY_QOS)
        self._progress_publisher = self.create_publisher(UInt64, RECORDED, PROGRESS_QOS)
        self._alive = Alive(self, NAME)
        self._progress = UInt64()
        self._timer = self.create_timer(0.02, self._poll)
        self.closed = False

    def _channel(self, topic: str) -> int:
        channel = self.channels.get(topic)
        if channel is None:
            type_name = bag.TOPIC_TYPES[topic]
            schema = self.writer.register_schema(name=type_name, encoding="ros2msg",
                                                 data=bag.schema_text(type_name).encode())
            qos = bag.qos_yaml([info.qos_profile
                                for info in self.get_publishers_info_by_topic(topic)])
            digest = bag.type_hash(type_name)
            channel = self.channels[topic] = self.writer.register_channel(
                topic=topic, message_encoding="cdr", schema_id=schema,
                metadata={"topic_type_hash": digest, "offered_qos_profiles": qos})
            self.topics.append({"name": topic, "type": type_name, "qos": qos, "hash": digest})
        return channel

    def _receiver(self, topic: str):
        def receive(data: bytes) -> None:
            now = time.time_ns()
            self.last_message_at = time.monotonic()
            channel = self.channels.get(topic) or self._channel(topic)
            stamp = bag.stamp_ns(data)
            self.writer.add_message(channel_id=channel, log_time=now, data=data,
                                    publish_time=stamp, sequence=self.counts[topic])
            if topic in PER_TICK:
                previous = self.last_tick.get(topic)
                if previous is not None and stamp > previous and self.tau_ns:
                    self.missing += max(0, round((stamp - previous) / self.tau_ns) - 1)
                self.last_tick[topic] = stamp
            self.counts[topic] += 1
            if self.first_ns is None:
                self.first_ns = now
            self.last_ns = now
            if topic == TRIAL_EVENT and self.episode_end_at is None and \
                    deserialize_message(data, TrialEvent).event == TrialEvent.EPISODE_END:
                self.episode_end_at = time.monotonic()
        return receive

    def _poll(self) -> None:
        """Announce readiness once every subscription sees its publisher; report progress;
        after EPISODE_END, finish when no message came for LINGER_S."""
        if self._ready_publisher is not None:
            if all(s.get_publisher_count() >= 1 for s in self.subscriptions_by_topic.values()):
                for topic in bag.TOPIC_TYPES:
                    self._channel(topic)
                self._ready_publisher.publish(String(data=NAME))
                self._ready_publisher = None
        if len(self.last_tick) == len(PER_TICK):  # sent each time: a lost one is replaced
            self._progress.data = min(self.last_tick.values()) // self.tau_ns
            self._progress_publisher.publish(self._progress)
        if self.episode_end_at is not None:
            now = time.monotonic()
            if now - self.last_message_at > LINGER_S or now - self.episode_end_at > LINGER_MAX_S:
                self.finish(0)

    def finish(self, code: int) -> None:
        if not self.finished.done():
            self.finished.set_result(code)

    def close(self) -> None:
        """Write the rosbag2 metadata record, the summary and the index (idempotent)."""
        if self.closed:
            return
        self.closed = True
        for topic in bag.TOPIC_TYPES:
            self._channel(topic)
        start = self.first_ns or time.time_ns()
        self.writer.add_metadata("rosbag2", {
            "serialized_metadata": bag.rosbag2_metadata(self.path, self.topics, self.counts,
                                                        start, self.last_ns or start),
            "ROS_DISTRO": "jazzy"})
        self.writer.finish()
        self.file.close()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv if argv is None else argv
    with ros_session(argv) as signals:
        try:
            node = RecorderNode()
        except (OSError, ValueError) as error:
            print(f"recorder: error: {error}", file=sys.stderr)
            return 2
        try:
            spin_until_finished([node], node.finished, signals)
            return 128 + signals[0] if signals else node.finished.result()
        finally:
            node.close()
            total = sum(node.counts.values())
            print(f"recorder: {total} messages in {node.path} "
                  f"({os.path.getsize(node.path) / 1e6:.2f} MB)", flush=True)
            if node.missing:
                print(f"recorder: warning: {node.missing} messages of per-tick topics never "
                      f"arrived (gaps in the ticks)", file=sys.stderr, flush=True)
            node.destroy_node()


if __name__ == "__main__":
    raise SystemExit(main())


# --- used by run_all -------------------------------------------------------------------------

def default_bag_path(out_dir: Path | None) -> Path:
    """<out>/run.mcap with --out, else bags/run_<UTC time>.mcap under the current directory."""
    if out_dir is not None:
        return Path(out_dir) / "run.mcap"
    return Path("bags") / time.strftime("run_%Y%m%d_%H%M%S.mcap", time.gmtime())


def launch(values: dict, bag_path: Path, workdir: Path):
    """Start the recorder process for a run_all run; OSError if the bag cannot be created."""
    import subprocess
    import yaml
    bag_path = Path(bag_path).resolve()
    bag_path.parent.mkdir(parents=True, exist_ok=True)
    open(bag_path, "wb").close()
    params_file = Path(workdir) / "recorder_params.yaml"
    params_file.write_text(yaml.safe_dump({"/**": {"ros__parameters": {**values,
                                                                       "bag_path": str(bag_path)}}}))
    return subprocess.Popen([sys.executable, "-m", "clnn_ros.nodes.recorder", "--ros-args",
                             "--params-file", str(params_file), "--log-level", "warn"])


def stop(process, status: int, grace_s: float = 5.0) -> None:
    """After the graph is done: the recorder ends by itself on EPISODE_END; after Ctrl-C, or if
    no EPISODE_END came (the trial manager itself died), it is told to finish the file."""
    import signal
    import subprocess
    if (status in (130, 143) or status < 0) and process.poll() is None:
        process.send_signal(signal.SIGINT)
    for sig, wait_s in ((None, grace_s), (signal.SIGTERM, 10.0), (signal.SIGKILL, 5.0)):
        if sig is not None and process.poll() is None:
            process.send_signal(sig)
        try:
            process.wait(timeout=wait_s)
            if sig is not None:  # stopped from outside: its Fast DDS files may be left
                remove_unused_fast_dds_files()
            return
        except subprocess.TimeoutExpired:
            pass
