"""Recorder node: every topic of the graph into one rosbag2 bag directory (clnn_ros.bag), as
`ros2 bag record -s mcap -o NAME` writes it: NAME/metadata.yaml and NAME/NAME_0.mcap.

    python -m clnn_ros.nodes.recorder --ros-args -p bag_path:=NAME [--params-file P]

It subscribes raw (the CDR bytes, never decoded) to clock, trial/event, env/observation,
cartpole/markers, rln/spikes, rln/reward, rln/action and rln/weights (in its namespace) with a deep
reader queue, and to the latched env/task and rln/input_labels (names.LATCHED), and announces
"recorder" on _graph/ready once each subscription but the optional cartpole/markers'
(names.OPTIONAL: another task, or an environment of one's own, may not publish it) sees its
publisher (again every second until the first clock); run_all makes the trial manager wait for it
and every publisher of the graph wait for its subscription (run setting extra_nodes), so the first
tick is recorded. Every 20 ms it publishes on _recorder/progress the last tick it holds on every
per-tick topic; the trial manager keeps the graph within RECORDER_WINDOW ticks of it, so a slow
recorder loses nothing. Each message keeps its receive time (log_time) and its publisher's source
timestamp (publish_time), as Jazzy's recorder does. The bag is finished (rosbag2 metadata, summary,
index, metadata.yaml) on EPISODE_END (a normal end, or a stall the trial manager detected), on
Ctrl-C, on SIGTERM and when run_all goes away. A chunk goes to the file half a second after its
first message (bag.CHUNK_SECONDS), so a SIGKILL loses at most that; `python -m clnn_ros.bag repair`
then makes a finished copy. A bag that holds no message is removed. The run's parameters are stored
in the bag's `clnn_ros` metadata record, with the environment node (parameter `environment`).
Exit status 0 (also after SIGINT/SIGTERM: a requested stop), 2 for bad parameters, 1 if the bag cannot be written (a
full disk: one line).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.task import Future
from std_msgs.msg import UInt64

from clnn_ros_msgs.msg import TrialEvent

from .. import bag
from ..core.params import ParamError, Params
from ..files import describe_write_error
from ..graph import qos
from ..graph.names import (CLOCK, LATCHED, OPTIONAL, PER_TICK, RECORDED, RECORDER,
                           TOPIC_TYPES, TRIAL_EVENT)
from ..graph.fields import tick_nanoseconds
from ..graph.ticks import TICKS_RECORD, TickRanges
from ..session.rclpy_session import WithMessageInfo, qos_profile, ros_session, spin_until_finished
from .glue import (LABELS_QOS, PROGRESS_QOS, Readiness, declare_run_parameters,
                   given_parameters, steady_clock, use_sim_time)

RECORD_QOS = qos_profile(qos.RECORD)
LINGER_S = 0.3      # after EPISODE_END: wait for messages still in flight on other topics
LINGER_MAX_S = 2.0


class RecorderNode(Node):
    def __init__(self, run: dict, **node_options):
        super().__init__(RECORDER, **node_options)
        params, settings = declare_run_parameters(
            self, RECORDER, run, own={"bag_path": ("", "the bag directory the recorder writes"),
                       "environment": ("", "what ran as the environment node, kept in the bag "
                                       "(run_all sets it): cartpole, gymnasium, mujoco, "
                                       "gymnasium:ID, external or the --env-node command")})
        use_sim_time(self, RECORDER)  # log and receive times are wall-clock, as rosbag2's
        bag_path = settings.pop("bag_path")
        environment = settings.pop("environment")
        if not bag_path:
            raise ParamError("bag_path is not set (-p bag_path:=DIRECTORY)")
        self.path = Path(bag_path)
        self.failure = None  # why the bag could not be written (a full disk)
        self.bag = bag.BagWriter(self.path, "clnn_ros recorder")
        defaults = Params().to_dict()
        given = {k: list(v) if isinstance(v, tuple) else v
                 for k, v in params.to_dict().items() if v != defaults[k]}
        self.bag.add_metadata("clnn_ros", {
            "parameters": json.dumps({**given, **settings}, sort_keys=True),
            "namespace": self.get_namespace(), "environment": environment,
            "bag_format": "clnn_ros.bag"})
        self.channels = {}     # topic -> channel id
        self.counts = {topic: 0 for topic in TOPIC_TYPES}
        self.ticks = {topic: TickRanges() for topic in PER_TICK}  # the ticks each one holds
        self.latest = {}  # per-tick topic: its last tick
        self.subscriptions_by_topic = {}
        self.tau_ns = tick_nanoseconds(params.tau)
        for topic, type_name in TOPIC_TYPES.items():
            self.subscriptions_by_topic[topic] = self.create_subscription(
                bag.message_class(type_name), topic, self._receiver(topic),
                LABELS_QOS if topic in LATCHED else RECORD_QOS, raw=True)
        self.finished = Future()
        self.episode_end_at = None
        self.last_message_at = time.monotonic()
        # the graph runs once a clock was recorded: no more announcements
        self._ready = Readiness(self, self._ready_to_record, lambda: self.ticks[CLOCK].ranges)
        self._progress_publisher = self.create_publisher(UInt64, RECORDED, PROGRESS_QOS)
        self._progress = UInt64()
        self._timer = self.create_timer(0.02, self._poll, clock=steady_clock())
        self.closed = False

    def _channel(self, topic: str) -> int:
        channel = self.channels.get(topic)
        if channel is None:
            type_name = TOPIC_TYPES[topic]
            resolved = self.subscriptions_by_topic[topic].topic_name
            qos = bag.qos_dicts([info.qos_profile
                                 for info in self.get_publishers_info_by_topic(resolved)])
            channel = self.channels[topic] = self.bag.add_topic(
                resolved, type_name, bag.schema_text(type_name), qos, bag.type_hash(type_name))
        return channel

    def _open_channels(self) -> None:
        """A channel for every topic of the graph, even one without messages; for an optional
        one (OPTIONAL) only while a publisher offers it (its first message opened it anyway)."""
        for topic in TOPIC_TYPES:
            if topic not in OPTIONAL or self.subscriptions_by_topic[topic].get_publisher_count():
                self._channel(topic)

    def _ready_to_record(self) -> bool:
        """Ready once every topic the graph must have has a publisher: its channels are opened
        first (never, if the bag cannot be written)."""
        if self.failure or not all(s.get_publisher_count() >= 1 for topic, s in
                                   self.subscriptions_by_topic.items() if topic not in OPTIONAL):
            return False
        try:
            self._open_channels()
        except OSError as error:
            self._write_failed(error)
            return False
        return True

    def _write_failed(self, error: OSError) -> None:
        self.failure = describe_write_error(error, self.path)
        self.finish(1)

    def _receiver(self, topic: str):
        def receive(data: bytes, info: dict) -> None:
            if self.failure:
                return
            self.last_message_at = time.monotonic()
            try:
                self.bag.write(self._channel(topic), info["received_timestamp"],
                               info["source_timestamp"], data, self.counts[topic])
            except OSError as error:  # the graph ends: a bag with holes would be lost silently
                self._write_failed(error)
                return
            if topic in PER_TICK:
                tick = bag.tick_of(data, self.tau_ns, stamped=topic == CLOCK)
                self.ticks[topic].add(tick)
                self.latest[topic] = max(self.latest.get(topic, -1), tick)
            self.counts[topic] += 1
            if topic == TRIAL_EVENT and self.episode_end_at is None and self.ends_episode(data):
                self.episode_end_at = time.monotonic()
        return WithMessageInfo(receive)

    def ends_episode(self, data: bytes) -> bool:
        """An EPISODE_END of this graph's clock: its tick is the last clock's or the next (a
        stale one, or another graph's, records like any message but ends nothing)."""
        event = deserialize_message(data, TrialEvent)
        clock = self.held(CLOCK)
        return event.event == TrialEvent.EPISODE_END and clock <= event.tick <= clock + 1

    def held(self, topic: str) -> int:
        """The last tick of a per-tick topic (-1: none)."""
        return self.latest.get(topic, -1)

    def progress(self) -> int:
        """The last tick every per-tick topic reached: a forged one far ahead on some topics
        moves it not."""
        return min(self.held(topic) for topic in PER_TICK)

    def missing(self) -> int:
        """Messages of per-tick topics that never arrived: the ticks up to the progress that a
        topic lacks."""
        progress = self.progress()
        return sum(b - a + 1 for ticks in self.ticks.values()
                   for a, b in ticks.missing(0, progress))

    def _poll(self) -> None:
        """Announce readiness once every subscription sees its publisher; report progress; write
        out a chunk that is due though no message came; after EPISODE_END, finish when no
        message came for LINGER_S."""
        if not self.failure:
            try:
                self.bag.flush_if_due()
            except OSError as error:
                self._write_failed(error)
                return
        if (progress := self.progress()) >= 0:  # sent each time: a lost one is replaced
            self._progress.data = progress
            self._progress_publisher.publish(self._progress)
        if self.episode_end_at is not None:
            now = time.monotonic()
            if now - self.last_message_at > LINGER_S or now - self.episode_end_at > LINGER_MAX_S:
                self.finish(0)

    def finish(self, code: int) -> None:
        if not self.finished.done():
            self.finished.set_result(code)

    def close(self) -> str:
        """Finish the bag: the rosbag2 metadata record, the summary and the index, metadata.yaml
        (idempotent); a bag that holds no message is removed. Returns what became of the bag,
        one line."""
        if self.closed:
            return ""
        self.closed = True
        total = sum(self.counts.values())
        try:
            if not self.failure:
                self._open_channels()
                # what run_all compares with the run's ticks (graph.ticks)
                self.bag.add_metadata(TICKS_RECORD, {topic: json.dumps(ticks.ranges)
                                                     for topic, ticks in self.ticks.items()})
            self.bag.close(finalize=not self.failure)
        except OSError as error:
            self.failure = self.failure or describe_write_error(error, self.path)
        if total == 0:
            bag.remove_bag(self.path)
            return f"nothing recorded: {self.path} removed"
        if self.failure:
            return f"{total} messages in {self.path}, not finalized ({self.failure}; " \
                   f"`python -m clnn_ros.bag repair` copies its complete chunks)"
        return f"{total} messages in {self.path} " \
               f"({os.path.getsize(self.bag.path) / 1e6:.2f} MB)"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv if argv is None else argv
    with ros_session(argv) as signals:
        try:
            node = RecorderNode(given_parameters(argv))
        except ParamError as error:
            print(f"recorder: error: {error}", file=sys.stderr)
            return 2
        except OSError as error:
            print(f"recorder: error: {describe_write_error(error)}", file=sys.stderr)
            return 2
        status = 1
        try:
            spin_until_finished([node], node.finished, signals)
            status = 0 if signals else node.finished.result()  # a requested stop: 0
        finally:
            print(f"recorder: {node.close()}", flush=True)
            if node.failure:
                print(f"recorder: error: {node.failure}", file=sys.stderr, flush=True)
                status = 1
            if missing := node.missing():
                print(f"recorder: warning: {missing} messages of per-tick topics never "
                      f"arrived (gaps in the ticks)", file=sys.stderr, flush=True)
            node.destroy_node()
        return status


if __name__ == "__main__":
    raise SystemExit(main())
