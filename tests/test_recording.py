"""Recording (clnn_ros.nodes.recorder via run_all) into rosbag2 bag directories, reading them with
two independent readers and converting them with rosbags-convert, faults (Ctrl-C, a killed
recorder and its repaired bag) and the offline analysis (clnn_ros.analysis.analyze)."""

from __future__ import annotations

import array
import csv
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from clnn_ros import bag
from clnn_ros.graph import names
from clnn_ros.graph.names import STATE

from test_graph import processes_with, wait_for_line

from conftest import HANG_S, free_domain_id, ros_environment, tool

DOMAIN_ID = free_domain_id()
REPO = Path(__file__).resolve().parents[1]
SAMPLE = "sample_seed0_12trials"  # bags/SAMPLE/, the sample recording
PER_TICK = names.PER_TICK


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)


@pytest.fixture(scope="module")
def recorded(ros_env, tmp_path_factory):
    """One recorded run (seed 0, 12 trials, cap 2000: about 4,800 ticks) and its analysis."""
    out = tmp_path_factory.mktemp("recorded")
    run = subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--seed", "0",
                          "--trials", "12", "--max-steps", "2000", "--out", str(out)],
                         env=ros_env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert f"run_all: recording to {out / 'bag'}" in run.stdout
    assert f"run_all: bag {out / 'bag'}" in run.stdout
    analysis = subprocess.run([sys.executable, "-m", "clnn_ros.analysis", str(out / "bag"),
                               "--out", str(out / "analysis")], capture_output=True, text=True,
                              timeout=HANG_S)
    assert analysis.returncode == 0, analysis.stderr
    return out


def raw_messages(path: Path, salvage=False):
    """(schema, topic, tick, log_time, CDR bytes, recorded name) of each message in file order;
    the tick read as the recorder reads it (bag.tick_of)."""
    reader, stream = bag.open_bag(path, salvage)
    with stream:
        return [(schema, topic, bag.tick_of(data, 20_000_000, stamped=topic == names.CLOCK),
                 log_time, data, name)
                for schema, topic, log_time, data, name in bag.iter_raw(reader)]


def gaps(ticks: list[int]) -> str:
    """The first few departures of sorted ticks from 0, 1, 2, ... (a short assertion message)."""
    wrong = [(i, t) for i, t in enumerate(ticks) if t != i][:3]
    return f"{len(ticks)} ticks, first departures (position, tick): {wrong}"


def assert_every_tick(messages, topics=PER_TICK, last_state_tick=None, tail_allowance=0):
    """Each per-tick topic holds every tick from 0 to the last state's tick, no gap; but for
    the last `tail_allowance` ticks (what a process killed outright had not delivered yet)."""
    ticks = {t: sorted(m[2] for m in messages if m[1] == t) for t in topics}
    last = ticks[STATE][-1] if last_state_tick is None else last_state_tick
    whole = last + 1 - tail_allowance
    assert ticks[STATE][:whole] == list(range(whole)), f"{STATE}: {gaps(ticks[STATE])}"
    for topic in topics:
        head = ticks[topic][:whole - 1]
        assert head == list(range(len(head))), f"{topic}: {gaps(ticks[topic])}"
        assert len(ticks[topic]) >= whole - 1, topic  # the last tick's later messages may be missing
    return last


# --- the recorded run and its analysis ---------------------------------------------------------

@pytest.mark.ros
def test_analysis_equals_the_live_run(recorded):
    analysis = recorded / "analysis"
    assert (analysis / "trials.csv").read_text() == (recorded / "trials.csv").read_text()
    np.testing.assert_array_equal(np.load(analysis / "final_weights.npy"),
                                  np.load(recorded / "final_weights.npy"))
    for name in ("learning_curve.png", "raster.png", "traces.png", "weights.png", "summary.md"):
        assert (analysis / name).stat().st_size > 1000, name
    with open(analysis / "weights.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 12 * 2 * 3 * 6  # a snapshot after each trial
    summary = (analysis / "summary.md").read_text()
    assert "trials completed: 12; mean successful steps 396.3" in summary
    assert "EPISODE_END, `completed`" in summary
    # contract version 4: the task as env/task describes it, the observations by their type
    assert "* task: `cartpole` (the environment's env/task): 4 variables `cart_position` m " \
           "[-2.4, 2.4], `cart_velocity` m/s, `pole_angle` deg [-12, 12]" in summary
    assert "| `/env/task` | `clnn_ros_msgs/msg/TaskDescription` | 1 | - | - |" in summary
    assert "| `/env/observation` | `clnn_ros_msgs/msg/Observation` | 4,779 | 0-4778 | 0 |" in \
        summary
    assert "cartpole/state" not in summary


@pytest.mark.ros
def test_bag_layout_is_rosbag2(recorded):
    """Schemas, hashes, QoS and the rosbag2 metadata record, as ros2 bag writes them."""
    from mcap.reader import make_reader
    with open(recorded / "bag" / "bag_0.mcap", "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    channels = {names.graph_topic(c.topic): c for c in summary.channels.values()}
    assert {c.topic for c in channels.values()} == {names.absolute(t) for t in names.TOPIC_TYPES}
    for topic, type_name in names.TOPIC_TYPES.items():
        channel = channels[topic]
        schema = summary.schemas[channel.schema_id]
        assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
        assert schema.name == type_name
        assert channel.metadata["topic_type_hash"] == bag.type_hash(type_name)
        assert channel.metadata["topic_type_hash"].startswith("RIHS01_")
        qos = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        latched = topic in names.LATCHED  # published once: kept for late subscribers
        assert qos[0]["reliability"] == "reliable" and \
            qos[0]["durability"] == ("transient_local" if latched else "volatile")
        assert qos[0]["history"] == "unknown"  # DDS does not tell a publisher's history
    # a schema holds its dependencies' definitions (the state has none: no Header)
    text = summary.schemas[channels[names.CLOCK].schema_id].data.decode()
    assert "\n" + "=" * 80 + "\nMSG: builtin_interfaces/Time\n" in text
    assert "\nMSG: " not in summary.schemas[channels[STATE].schema_id].data.decode()
    assert summary.chunk_indexes and all(c.compression == "zstd" for c in summary.chunk_indexes)
    # The last `rosbag2` record (rosbag2 also writes one when the bag opens) is metadata.yaml's,
    # but for the notes run_all adds to metadata.yaml once the run has ended (custom_data).
    info = yaml.safe_load(metadata["rosbag2"]["serialized_metadata"])
    on_disk = yaml.safe_load((recorded / "bag" / "metadata.yaml").read_text())
    notes = on_disk["rosbag2_bagfile_information"].pop("custom_data")
    assert info.pop("custom_data") is None and set(notes) == {"clnn_ros.run_end",
                                                              "clnn_ros.run_last_tick"}
    assert {"rosbag2_bagfile_information": info} == on_disk
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["bag_0.mcap"] and info["ros_distro"] == "jazzy"
    assert info["message_count"] == summary.statistics.message_count == \
        info["files"][0]["message_count"]
    assert info["starting_time"]["nanoseconds_since_epoch"] == \
        summary.statistics.message_start_time
    assert info["duration"]["nanoseconds"] == \
        summary.statistics.message_end_time - summary.statistics.message_start_time
    counts = {t["topic_metadata"]["name"]: t["message_count"]
              for t in info["topics_with_message_count"]}
    assert counts == {channels[t].topic: summary.statistics.channel_message_counts[channels[t].id]
                      for t in channels}
    for topic in info["topics_with_message_count"]:  # version 9: a list, the channel's QoS
        metadata_qos = topic["topic_metadata"]["offered_qos_profiles"]
        channel = channels[names.graph_topic(topic["topic_metadata"]["name"])]
        assert isinstance(metadata_qos, list) and metadata_qos == \
            yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert topic["topic_metadata"]["type_description_hash"] == \
            channel.metadata["topic_type_hash"]
    assert '"seed": 0' in metadata["clnn_ros"]["parameters"]


def read_all_with_rosbags(path: Path) -> int:
    """Every message of a bag decoded by rosbags' AnyReader (from the schemas in the bag)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    count = 0
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for connection, _, data in reader.messages():
            reader.deserialize(data, connection.msgtype)
            count += 1
    return count


@pytest.mark.ros
def test_rosbags_reads_and_converts_a_run(ros_env, tmp_path):
    """The acceptance run: its bag directory is rosbag2 version 9 (QoS profiles as YAML lists);
    rosbags decodes every message, and rosbags-convert to sqlite3 and back keeps them all."""
    run = subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--seed", "1",
                          "--trials", "32", "--out", str(tmp_path)], env=ros_env,
                         capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr
    recorded = tmp_path / "bag"
    info = yaml.safe_load((recorded / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["bag_0.mcap"]
    ticks = json.loads((tmp_path / "summary.json").read_text())["ticks"]
    assert info["custom_data"] == {"clnn_ros.run_end": "completed",  # noted by run_all
                                   "clnn_ros.run_last_tick": str(ticks - 1)}
    assert {t["topic_metadata"]["name"] for t in info["topics_with_message_count"]} == \
        {names.absolute(t) for t in names.TOPIC_TYPES}
    for topic in info["topics_with_message_count"]:
        profiles = topic["topic_metadata"]["offered_qos_profiles"]
        assert isinstance(profiles, list) and profiles[0]["reliability"] == "reliable"
    count = read_all_with_rosbags(recorded)
    assert count == info["message_count"] > 0
    convert = shutil.which("rosbags-convert", path=str(Path(sys.executable).parent))
    for source, destination, storage in ((recorded, tmp_path / "as_sqlite3", "sqlite3"),
                                         (tmp_path / "as_sqlite3", tmp_path / "back", "mcap")):
        result = subprocess.run([convert, "--src", str(source), "--dst", str(destination),
                                 "--dst-storage", storage], capture_output=True, text=True,
                                timeout=120)
        assert result.returncode == 0, result.stdout + result.stderr
        assert read_all_with_rosbags(destination) == count, destination
    assert list((tmp_path / "as_sqlite3").glob("*.db3"))


def plain(value):
    """A decoded field as plain Python, whichever reader decoded it (NaN as "nan", which
    compares equal: the cart-pole's description has no reward threshold)."""
    if isinstance(value, (float, np.floating)) and math.isnan(value):
        return "nan"
    if isinstance(value, (bytes, bytearray, array.array)):
        return list(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, "__slots__") or hasattr(value, "__dataclass_fields__"):
        return fields_of(value)
    if isinstance(value, (np.generic,)):
        return value.item()
    return value


def fields_of(msg) -> dict:
    if hasattr(msg, "get_fields_and_field_types"):  # rclpy
        names = list(msg.get_fields_and_field_types())
    elif hasattr(msg, "__dataclass_fields__"):  # rosbags
        names = [n for n in msg.__dataclass_fields__ if n != "__msgtype__"]
    else:  # mcap_ros2
        names = [n for n in msg.__slots__]
    return {n: plain(getattr(msg, n)) for n in names
            if not n.isupper() and n != "__msgtype__"}


@pytest.mark.ros
def test_two_independent_readers_decode_every_field(recorded):
    """mcap_ros2 and rosbags, each from the schemas in the bag, agree field by field with the
    installed message types on sampled messages of every topic."""
    from mcap_ros2.reader import read_ros2_messages
    from rclpy.serialization import deserialize_message
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    from mcap.reader import make_reader

    path = recorded / "bag" / "bag_0.mcap"
    raw = {}  # (topic, sequence) -> CDR; the recorder numbers each topic's messages 0, 1, ...
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            raw[(names.graph_topic(channel.topic), message.sequence)] = message.data
            # as rosbag2: the publisher's source timestamp, then the receive time (wall clock)
            assert 0 < message.publish_time <= message.log_time
    by_mcap = {}
    for m in read_ros2_messages(path):
        key = (names.graph_topic(m.channel.topic), m.sequence_count)
        if key[1] % 97 == 3 or key[0] in (names.TRIAL_EVENT, names.WEIGHTS, *names.LATCHED):
            by_mcap[key] = fields_of(m.ros_msg)
    by_rosbags = {}
    seen = {}
    with AnyReader([recorded / "bag"],
                   default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for connection, _, data in reader.messages():
            topic = names.graph_topic(connection.topic)
            index = seen[topic] = seen.get(topic, -1) + 1
            if (topic, index) in by_mcap:
                by_rosbags[(topic, index)] = fields_of(
                    reader.deserialize(data, connection.msgtype))
    assert set(by_rosbags) == set(by_mcap)
    assert {t for t, _ in by_mcap} == set(names.TOPIC_TYPES)
    for (topic, index), fields in by_mcap.items():
        installed = fields_of(deserialize_message(raw[(topic, index)],
                                                  bag.message_class(names.TOPIC_TYPES[topic])))
        assert fields == installed, (topic, index)
        assert by_rosbags[(topic, index)] == installed, (topic, index)
        if "tick" in fields:  # read without decoding, as the recorder and analyze read it
            assert bag.tick_of(raw[(topic, index)], 20_000_000) == fields["tick"]
        elif topic == names.CLOCK:
            clock = fields["clock"]
            assert bag.tick_of(raw[(topic, index)], 20_000_000, stamped=True) == \
                (clock["sec"] * 10**9 + clock["nanosec"]) // 20_000_000


# --- faults ------------------------------------------------------------------------------------

def start_run(env, out: Path, *extra):
    return subprocess.Popen(
        [sys.executable, "-m", "clnn_ros.run_all", "--seed", "1", "--trials", "400",
         "--out", str(out), *extra], env={**env, "CLNN_TEST_RUN": str(out)},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def child(process, module: str) -> int:
    found = subprocess.run(["pgrep", "-P", str(process.pid), "-f", module],
                           capture_output=True, text=True).stdout.split()
    if len(found) != 1:
        process.kill()
        stdout, stderr = process.communicate(timeout=30)
        pytest.fail(f"{len(found)} processes of {module}; run_all: {process.returncode}\n"
                    f"{stdout[-1500:]}\n{stderr[-1500:]}")
    return int(found[0])


def listed_topics(env, wanted: set[str], *args) -> set[str]:
    """clnn_ros.live.topics' lines once they include `wanted`: it lists what discovery has found
    once
    it settled, and a run's participants may still be starting. On a loaded machine discovery
    can take over 10 s (clnn_ros.live.topics.DEFAULT_WAIT_S)."""
    deadline, lines = time.monotonic() + HANG_S, set()
    while not wanted <= lines and time.monotonic() < deadline:
        listed = tool(env, "clnn_ros.live.topics", *args)
        assert listed.returncode == 0, listed.stderr
        lines = set(listed.stdout.splitlines())
    assert wanted <= lines, f"never listed: {sorted(wanted - lines)}; last: {listed.stderr}"
    return lines


@pytest.mark.ros
def test_echo_topics_then_ctrl_c_leaves_a_complete_bag(ros_env, tmp_path):
    """Against a live graph: clnn_ros.live.topics and clnn_ros.live.echo (YAML, --field, --raster,
    Ctrl-C,
    an unknown topic); then Ctrl-C to the whole run leaves a finished bag."""
    process = start_run(ros_env, tmp_path)
    wait_for_line(process.stdout, "trial    3/", errors=process.stderr)
    # The model's topics, and ROS's own: the plumbing is hidden (names with a part "_...").
    graph = {f"{names.absolute(topic)} [{type_name}]" for topic, type_name in names.TOPIC_TYPES.items()
             } | {"/parameter_events [rcl_interfaces/msg/ParameterEvent]",
                  "/rosout [rcl_interfaces/msg/Log]"}
    assert listed_topics(ros_env, graph) == graph
    plumbing = {"/_graph/ready [std_msgs/msg/String]", "/_graph/claim [std_msgs/msg/String]",
                "/_recorder/progress [std_msgs/msg/UInt64]"}
    assert listed_topics(ros_env, graph | plumbing, "--include-hidden-topics") == graph | plumbing
    state = tool(ros_env, "clnn_ros.live.echo", names.absolute(STATE), "--once")
    assert state.returncode == 0 and state.stdout.endswith("\n---\n")
    fields = yaml.safe_load(state.stdout.split("---")[0])
    assert list(fields) == ["tick", "trial", "values", "reward", "terminated", "truncated",
                            "termination", "successful_steps"]
    assert len(fields["values"]) == 4
    # latched, long sent: the task, whose variables name the values
    task = tool(ros_env, "clnn_ros.live.echo", names.absolute(names.TASK), "--once")
    described = yaml.safe_load(task.stdout.split("---")[0])
    assert described["variable_names"] == ["cart_position", "cart_velocity", "pole_angle",
                                           "pole_angular_velocity"], task.stdout
    assert described["contract_version"] == 4 and described["action_labels"] == ["-F", "+F"]
    angle = tool(ros_env, "clnn_ros.live.echo", names.absolute(STATE), "--once", "--field",
                 "values[2]")  # the pole angle, deg
    assert abs(yaml.safe_load(angle.stdout.split("---")[0])) < 20, angle.stdout  # 12: a limit
    spikes = tool(ros_env, "clnn_ros.live.echo", "/rln/spikes", "--once")
    assert "\nspikes:\n- " in spikes.stdout and "label" not in spikes.stdout
    # latched: long sent
    labels = tool(ros_env, "clnn_ros.live.echo", "/rln/input_labels", "--once")
    assert labels.stdout.startswith("labels:\n- pole_angle[-inf,-6)deg\n"), labels.stdout
    tick = tool(ros_env, "clnn_ros.live.echo", "/rln/action", "--once", "--field", "tick")
    assert isinstance(yaml.safe_load(tick.stdout.split("---")[0]), int), tick.stdout
    # Marked as the run's: if a wait below fails, the test's cleanup stops it too.
    raster = subprocess.Popen([sys.executable, "-m", "clnn_ros.live.echo", "/rln/spikes",
                               "--raster"],
                              env={**ros_env, "CLNN_TEST_RUN": str(tmp_path)},
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for_line(raster.stdout, "|", timeout=120)
    line = wait_for_line(raster.stdout, "tick ", timeout=120)
    raster.send_signal(signal.SIGINT)
    _, raster_err = raster.communicate(timeout=10)
    assert raster.returncode == 130 and "Traceback" not in raster_err
    assert line.count("#") == 1 and line.rstrip().endswith("|") and " trial " in line
    unknown = tool(ros_env, "clnn_ros.live.echo", "/no/such/topic", "--wait", "0.5")
    assert unknown.returncode == 1 and len(unknown.stderr.strip().splitlines()) == 1
    assert "unknown topic '/no/such/topic'" in unknown.stderr
    bad_name = tool(ros_env, "clnn_ros.live.echo", "/no such topic")
    assert bad_name.returncode == 1 and bad_name.stderr.startswith(
        "echo: error: '/no such topic' is not a topic name: ") and "Traceback" not in bad_name.stderr
    # A graph topic in another namespace is known without discovery: its fields are checked.
    bad_field = tool(ros_env, "clnn_ros.live.echo", "/robot1/rln/action", "--field",
                     "no_such_field")
    assert bad_field.returncode == 1 and "no_such_field" in bad_field.stderr

    os.killpg(process.pid, signal.SIGINT)
    _, stderr = process.communicate(timeout=HANG_S)
    assert process.returncode == 130 and "Traceback" not in stderr, stderr
    messages = raw_messages(tmp_path / "bag")  # finished: summary and index present
    assert assert_every_tick(messages) > 50
    assert not processes_with(str(tmp_path))


def chunk_state_counts(path: Path) -> list[int]:
    """The state messages (env/observation, one per tick) of each complete chunk of an MCAP file
    that may end in an unfinished one, in file order."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Chunk, Message
    from mcap.stream_reader import StreamReader, breakup_chunk
    counts, state_channels = [], set()
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, emit_chunks=True).records:
                if isinstance(record, Chunk):
                    inner = breakup_chunk(record)
                    state_channels |= {r.id for r in inner if isinstance(r, Channel)
                                       and names.graph_topic(r.topic) == STATE}
                    counts.append(sum(isinstance(r, Message) and r.channel_id in state_channels
                                      for r in inner))
        except McapError:  # the end of what the recorder wrote
            pass
    return counts


class Progress:
    """The recorder's progress (the last tick it holds on every per-tick topic), as
    clnn_ros.live.echo prints it from /_recorder/progress."""

    def __init__(self, env, run_dir: Path):
        self.process = subprocess.Popen(
            [sys.executable, "-m", "clnn_ros.live.echo", "/" + names.RECORDED, "--wait", "180"],
            env={**env, "CLNN_TEST_RUN": str(run_dir)}, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True)
        self.last = None
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.process.stdout:
            if line.startswith("data: "):
                self.last = int(line.split()[1])

    def stop(self):
        self.process.send_signal(signal.SIGINT)
        self.process.communicate(timeout=30)


@pytest.mark.ros
@pytest.mark.parametrize("moment", ["first chunk", "tick 3000"])
def test_killed_recorders_bag_is_repaired(ros_env, tmp_path, moment):
    """SIGKILL of the recorder early (as soon as its first chunk is on disk, half a second of
    ticks in) and later: `python -m clnn_ros.bag repair` makes a finished bag of it that mcap and
    rosbags read, every tick of its complete chunks; later, up to one or two chunks (half a
    second each) before what the recorder held when it was killed (its progress)."""
    from mcap.reader import make_reader
    process = start_run(ros_env, tmp_path)
    broken = tmp_path / "bag"
    early = moment == "first chunk"
    progress = None if early else Progress(ros_env, tmp_path)  # echo starts too late for early
    deadline = time.monotonic() + 180  # a hang bound
    while time.monotonic() < deadline:
        # a chunk with states (the input labels, latched, may come half a second earlier)
        if early and (broken / "bag_0.mcap").is_file() and any(chunk_state_counts(
                broken / "bag_0.mcap")):
            break
        if not early and (progress.last or 0) >= 3000:
            break
        time.sleep(0.01)
    os.kill(child(process, "clnn_ros.nodes.recorder"), signal.SIGKILL)
    if progress is not None:
        held = progress.last  # what the recorder held at least
        progress.stop()
    time.sleep(0.5)
    os.killpg(process.pid, signal.SIGINT)
    stdout, stderr = process.communicate(timeout=HANG_S)
    assert "node 'recorder' died (SIGKILL)" in stderr, stderr
    assert not (broken / "metadata.yaml").exists()
    with pytest.raises(bag.BagError, match="truncated"):
        bag.open_bag(broken)
        pytest.fail(f"the bag is complete\n{stdout[-2000:]}\n{stderr[-2000:]}")
    chunks = chunk_state_counts(broken / "bag_0.mcap")

    result = tool(ros_env, "clnn_ros.bag", "repair", broken)
    fixed = tmp_path / "bag_repaired"
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    assert result.stdout.startswith("bag: ") and f"in {fixed}" in result.stdout
    info = yaml.safe_load((fixed / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["relative_file_paths"] == ["bag_repaired_0.mcap"]
    with open(fixed / "bag_repaired_0.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == info["message_count"] == \
        read_all_with_rosbags(fixed)
    messages = raw_messages(fixed)
    assert info["message_count"] == len(messages) == len(raw_messages(broken, salvage=True))
    last = assert_every_tick(messages)
    assert last + 1 == sum(chunks)  # every complete chunk, nothing else
    if early:  # earlier than the other moment; how many chunks is up to the scheduler: beside
        # another worker's graph this test noticed the first chunk over a second late (4 chunks)
        assert sum(chunks) < 3000, chunks
    else:
        assert held - last <= 2 * max(chunks) + 50, (held, last, chunks)  # + progress' lag
        result = subprocess.run([sys.executable, "-m", "clnn_ros.analysis", str(broken), "--out",
                                 str(tmp_path / "a"), "--salvage"], capture_output=True,
                                text=True, timeout=HANG_S)
        assert result.returncode == 0, result.stderr
        assert "salvaged" in (tmp_path / "a" / "summary.md").read_text()
    assert not processes_with(str(tmp_path))


def test_repair_refuses_bad_input_with_one_line(tmp_path):
    text = tmp_path / "text.mcap"
    text.write_text("not a bag\n")
    (tmp_path / "empty_dir").mkdir()
    header_only = tmp_path / "header_only.mcap"
    header_only.write_bytes((REPO / "bags" / SAMPLE / f"{SAMPLE}_0.mcap").read_bytes()[:200])
    cases = ((tmp_path / "missing", "no such file or directory"),
             (text, "not an MCAP file"),
             (tmp_path / "empty_dir", "no .mcap file in the directory"),
             (header_only, "no complete chunk"))
    for path, message in cases:
        result = subprocess.run([sys.executable, "-m", "clnn_ros.bag", "repair", str(path)],
                                capture_output=True, text=True, timeout=HANG_S)
        assert result.returncode == 1, (path, result.stderr)
        assert message in result.stderr and "Traceback" not in result.stderr, result.stderr
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty_dir", "header_only.mcap",
                                                         "text.mcap"]  # no half-written copy
    result = subprocess.run([sys.executable, "-m", "clnn_ros.bag", "repair",
                             str(REPO / "bags" / SAMPLE), "--out", str(tmp_path / "empty_dir")],
                            capture_output=True, text=True, timeout=HANG_S)
    assert result.returncode == 1 and "exists" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_repair_on_a_full_disk_says_where_it_could_not_write(tmp_path):
    """--out on a 32 KB tmpfs (a mount namespace of its own), the sample bag bigger: one line
    naming the place and what to do, and no half-written copy left there."""
    full = tmp_path / "full"
    full.mkdir()
    out = full / "copy"
    script = 'mount -t tmpfs -o size=32k tmpfs "$FULL" || exit 99; "$@"; code=$?; ls -A "$FULL"; ' \
             'exit $code'
    result = subprocess.run(
        ["unshare", "--mount", "sh", "-c", script, "_", sys.executable, "-m", "clnn_ros.bag",
         "repair", str(REPO / "bags" / SAMPLE), "--out", str(out)],
        env={**os.environ, "FULL": str(full)}, capture_output=True, text=True, timeout=HANG_S)
    if result.returncode == 99:
        pytest.skip("no mount namespace here")
    assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr
    assert result.stderr.strip() == f"bag: error: disk full writing {out}: nothing kept there; " \
                                    f"give --out DIR on a disk with room"
    assert result.stdout.strip() == ""  # the tmpfs holds nothing: no half-written copy


# --- analyze: bad input ------------------------------------------------------------------------

def analyze(*args):
    return subprocess.run([sys.executable, "-m", "clnn_ros.analysis", *map(str, args)],
                          capture_output=True, text=True, timeout=HANG_S)


@pytest.mark.ros
def test_analyze_refuses_bad_bags_with_one_line(recorded, tmp_path):
    good = recorded / "bag" / "bag_0.mcap"
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    text = tmp_path / "text.mcap"
    text.write_text("not a bag\n")
    (tmp_path / "no_bag").mkdir()
    for path, status, message in ((tmp_path / "missing.mcap", 1, "no such file"),
                                  (text, 1, "not an MCAP file"),
                                  (truncated, 1, "truncated"),
                                  (tmp_path / "empty.mcap", 1, "not an MCAP file"),
                                  (tmp_path / "no_bag", 1, "no .mcap file in the directory")):
        if path.name == "empty.mcap":
            path.write_bytes(b"")
        result = analyze(path, "--out", tmp_path / "x")
        assert result.returncode == status, result.stderr
        assert message in result.stderr and "Traceback" not in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1
    result = analyze(recorded / "bag", "--out", tmp_path / "x", "--trial", "99")
    assert result.returncode == 2 and "trial 99 is not in the bag" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


# --- the sample recording in bags/ -------------------------------------------------------------

def test_sample_bag_analysis(tmp_path):
    sample = REPO / "bags" / SAMPLE
    if not sample.exists():
        pytest.skip("no sample bag")
    result = analyze(sample, "--out", tmp_path)
    assert result.returncode == 0, result.stderr
    with open(tmp_path / "trials.csv") as f:
        steps = [int(r["steps"]) for r in csv.DictReader(f)]
    assert steps == [32, 34, 288, 33, 278, 260, 264, 291, 259, 250, 2000, 767]
    assert math.isclose(np.mean(steps), 396.33, abs_tol=0.01)
    assert "| `/cartpole/state` | `clnn_ros_msgs/msg/CartPoleState` | 4,779 | 0-4778 | 0 |" in \
        (tmp_path / "summary.md").read_text()
    alone = analyze(sample / f"{SAMPLE}_0.mcap", "--out", tmp_path / "from_file")  # its .mcap
    assert alone.returncode == 0, alone.stderr
    assert (tmp_path / "from_file" / "trials.csv").read_text() == \
        (tmp_path / "trials.csv").read_text()


# The sample's messages table: a bag of contract version 3 (cartpole/state, no env/task)
SAMPLE_MESSAGES = """\
| topic | type | messages | ticks | missing ticks |
|---|---|---:|---|---:|
| `/clock` | `rosgraph_msgs/msg/Clock` | 4,779 | 0-4778 | 0 |
| `/trial/event` | `clnn_ros_msgs/msg/TrialEvent` | 25 | - | - |
| `/cartpole/state` | `clnn_ros_msgs/msg/CartPoleState` | 4,779 | 0-4778 | 0 |
| `/cartpole/markers` | `visualization_msgs/msg/MarkerArray` | 956 | - | - |
| `/rln/spikes` | `clnn_ros_msgs/msg/SpikeVector` | 4,779 | 0-4778 | 0 |
| `/rln/reward` | `clnn_ros_msgs/msg/Reward` | 4,779 | 0-4778 | 0 |
| `/rln/action` | `clnn_ros_msgs/msg/Action` | 4,779 | 0-4778 | 0 |
| `/rln/weights` | `clnn_ros_msgs/msg/WeightSnapshot` | 12 | - | - |
| `/rln/input_labels` | `clnn_ros_msgs/msg/InputLabels` | 1 | - | - |
"""


def test_a_bag_of_contract_version_3_is_analyzed_as_before(tmp_path):
    """The sample, recorded before contract version 4 (CartPoleStates on cartpole/state, Actions
    by force direction, no env/task): its task is the paper's cart-pole, its summary as it was
    (the messages of its own version, no task line), its trial's series the cart-pole's."""
    from clnn_ros.analysis.data import is_cartpole, read_bag, trial_returns, trial_series
    sample = REPO / "bags" / SAMPLE
    if not sample.exists():
        pytest.skip("no sample bag")
    result = analyze(sample, "--out", tmp_path, "--trial", "11")
    assert result.returncode == 0, result.stderr
    summary = (tmp_path / "summary.md").read_text()
    assert SAMPLE_MESSAGES in summary and "env/" not in summary and "* task:" not in summary
    assert "| trial | initial angle (deg) | steps | end |\n|---:|---:|---:|---|\n" \
           "| 0 | 1.20968 | 32 | cart_position |" in summary
    assert "* trial ends: cart_position 11, max_steps 1" in summary
    assert "Ticks 4010-4778 (769 states in the bag), 767 successful steps, ended by " \
           "cart_position." in summary
    data = read_bag(sample, salvage=False)
    assert is_cartpole(data) and data["state_type"] == "clnn_ros_msgs/msg/CartPoleState"
    assert data["task"].termination_reasons == ("pole_angle", "cart_position")
    assert trial_returns(data) == {}  # its states carry no reward
    series = trial_series(data, 11)
    assert series.cartpole and [v.name for v in series.variables] == [
        "cart_position", "cart_velocity", "pole_angle", "pole_angular_velocity"]
    assert [(v.low, v.high) for v in series.variables[::2]] == [(-2.4, 2.4), (-12.0, 12.0)]
    assert set(series.actions[:-1]) == {-1, 1} and series.actions[-1] == 0  # force directions
    assert abs(series.states[-1, 0]) > 2.4 and series.end_reason == "cart_position"
    # its state channel by its relative name in any namespace, as the graph's topics
    assert [bag.relative_topic(name) for name in ("/cartpole/state", "/robot1/cartpole/state",
                                                  "/robot1/env/observation", "/other/topic")] \
        == ["cartpole/state", "cartpole/state", "env/observation", "/other/topic"]


def test_a_bag_of_before_the_lean_messages_is_analyzed(tmp_path):
    """The first two chunks of the sample bag as recorded on 2026-12-03, whose messages began
    with a std_msgs/Header (and named a failure in failure_reason): analyze reads their ticks
    from the stamps and the trials' ends from the words, as the live run had them."""
    result = analyze(REPO / "tests" / "data" / "header_era_seed0_2_chunks.mcap", "--salvage",
                     "--out", tmp_path)
    assert result.returncode == 0, result.stderr
    with open(tmp_path / "trials.csv") as f:
        rows = [(int(r["steps"]), r["end_reason"]) for r in csv.DictReader(f)]
    assert rows == [(32, "cart_position"), (34, "cart_position"), (288, "cart_position"),
                    (33, "cart_position")]  # the sample's first four trials
    summary = (tmp_path / "summary.md").read_text()
    assert "| `/cartpole/state` | `clnn_ros_msgs/msg/CartPoleState` | 566 | 0-565 | 0 |" in summary
    assert "* environment: not recorded in this bag" in summary  # recorded before it was kept
    assert "* physics: parameter physics=paper, integrator=semi_implicit" in summary


@pytest.mark.ros
def test_a_gymnasium_tasks_bag_holds_its_task_and_is_analyzed_by_its_names(ros_env, tmp_path):
    """Acrobot-v1 through the graph (3 trials of at most 100 steps): the bag holds its latched
    env/task and every tick's Observation; the analysis names its variables, units and actions
    as the description does, gives each trial's return (Acrobot: -1 a step but the goal's: the
    successful steps' negative), draws no cart-pole (its --animate is refused)."""
    from mcap_ros2.reader import read_ros2_messages
    from clnn_ros.analysis import figures as pictures
    from clnn_ros.analysis.data import is_cartpole, read_bag, trial_returns, trial_series
    run = subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--env",
                          "gymnasium:Acrobot-v1", "--seed", "3", "--trials", "3", "--max-steps",
                          "100", "--out", str(tmp_path)], env={**ros_env,
                         "CLNN_TEST_RUN": str(tmp_path)}, capture_output=True, text=True,
                         timeout=HANG_S)
    assert run.returncode == 0, run.stderr
    path = tmp_path / "bag"
    (task,) = [m.ros_msg for m in read_ros2_messages(path / "bag_0.mcap",
                                                     topics=[names.absolute(names.TASK)])]
    variables = ["cos_theta1", "sin_theta1", "cos_theta2", "sin_theta2", "theta1_dot",
                 "theta2_dot"]
    assert (task.contract_version, task.task, list(task.variable_names)) == \
        (4, "gymnasium:Acrobot-v1", variables)
    assert list(task.action_labels) == ["0", "1", "2"] and task.ends_in == "success"
    with open(tmp_path / "trials.csv") as f:
        steps = [int(r["steps"]) for r in csv.DictReader(f)]
    ticks = json.loads((tmp_path / "summary.json").read_text())["ticks"]
    messages = raw_messages(path)
    assert sorted(m[2] for m in messages if m[1] == STATE) == list(range(ticks))
    assert not [m for m in messages if m[1] == names.MARKERS]  # the cart-pole's own drawing

    result = analyze(path, "--out", tmp_path / "analysis")
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "analysis" / "trials.csv").read_text() == \
        (tmp_path / "trials.csv").read_text()
    summary = (tmp_path / "analysis" / "summary.md").read_text()
    assert "* task: `gymnasium:Acrobot-v1` (the environment's env/task): 6 variables " \
           "`cos_theta1` [-1, 1]," in summary and "`theta1_dot` rad/s [-12.5664, 12.5664]" in \
        summary
    assert "* environment: Gymnasium's Acrobot-v1 (`run_all --env gymnasium:Acrobot-v1`" in \
        summary
    assert "| trial | steps | end | return |" in summary and "markers" not in summary
    for trial, count in enumerate(steps):
        assert f"| {trial} | {count:,} | " in summary and f" | {-count:g} |" in summary
    assert f"`traces.png`: trial {int(np.argmax(steps))} against the tick: " \
           f"{', '.join(variables)}, the action" in summary
    data = read_bag(path, salvage=False)
    assert not is_cartpole(data) and trial_returns(data) == {
        trial: -float(count) for trial, count in enumerate(steps)}
    series = trial_series(data, 0)
    assert [v.name for v in series.variables] == variables
    assert series.action_labels == ("0", "1", "2") and not series.cartpole
    assert set(series.actions[:-1]) <= {0, 1, 2} and np.isnan(series.actions[-1])
    fig = pictures.traces_figure(series, "traces")
    try:
        labels = [ax.get_ylabel() for ax in fig.axes]
        assert labels[:6] == ["cos theta1", "sin theta1", "cos theta2", "sin theta2",
                              "theta1 dot (rad/s)", "theta2 dot (rad/s)"]
        assert [t.get_text() for t in fig.axes[6].get_yticklabels()] == ["0", "1", "2"]
    finally:
        pictures.plt.close(fig)
    refused = analyze(path, "--out", tmp_path / "gif", "--animate", "0")
    assert refused.returncode == 2 and "--animate draws the cart-pole" in refused.stderr
    assert not (tmp_path / "gif").exists()
    assert not processes_with(str(tmp_path))


@pytest.mark.ros
def test_sigterm_stops_a_recorder_that_recorded_nothing(ros_env, tmp_path):
    """A recorder alone (no graph yet) told to stop with SIGTERM: a clean exit, and no bag,
    since nothing was recorded."""
    path = tmp_path / "alone"
    process = subprocess.Popen([sys.executable, "-m", "clnn_ros.nodes.recorder", "--ros-args",
                                "-p", f"bag_path:={path}"], env=ros_env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 20
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    process.send_signal(signal.SIGTERM)
    stdout, stderr = process.communicate(timeout=20)
    assert process.returncode == 0 and "Traceback" not in stderr, stderr  # a requested stop
    assert f"recorder: nothing recorded: {path} removed" in stdout and not path.exists()
    missing = subprocess.run([sys.executable, "-m", "clnn_ros.nodes.recorder"], env=ros_env,
                             capture_output=True, text=True, timeout=20)
    assert missing.returncode == 2 and "bag_path is not set" in missing.stderr
