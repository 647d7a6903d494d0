"""The live view (docs/RECORDING.md, "Live view"): the environment node draws the cart-pole as a
visualization_msgs MarkerArray in frame `world` on cartpole/markers, recorded in the bag; decoded
from the bag, each tick's markers show that tick's recorded state. An environment node of one's
own without markers (the example) still runs the graph and is recorded."""

from __future__ import annotations

import math
import random
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from builtin_interfaces.msg import Time

from clnn_ros.graph import names
from clnn_ros.graph.run import RUN_SETTINGS
from clnn_ros.core.params import STATE_NAMES
from clnn_ros.nodes.markers import CART, CART_SIZE_M, FRAME, NAMESPACE, POLE, TRACK, CartPoleMarkers

from conftest import HANG_S, free_domain_id, ros_environment

ROOT = Path(__file__).resolve().parents[1]
DOMAIN_ID = free_domain_id()
POLE_HALF_LENGTH_M = 0.326  # the paper's, the run's default
# The cart-pole's observation values (env/observation, in env/task's order): what the markers draw
POSITION, ANGLE = STATE_NAMES.index("cart_position"), STATE_NAMES.index("pole_angle")


def rotate(q, v):
    """v rotated by the unit quaternion q (x, y, z, w)."""
    x, y, z, w = q
    # v' = v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)
    cx, cy, cz = y * v[2] - z * v[1], z * v[0] - x * v[2], x * v[1] - y * v[0]
    return (v[0] + 2 * (w * cx + y * cz - z * cy), v[1] + 2 * (w * cy + z * cx - x * cz),
            v[2] + 2 * (w * cz + x * cy - y * cx))


def pole_ends(pole):
    """(hinge, tip) of the pole cylinder: its centre -+ half its length along its local z."""
    o = pole.pose.orientation
    axis = rotate((o.x, o.y, o.z, o.w), (0.0, 0.0, pole.scale.z / 2))
    p = pole.pose.position
    return ((p.x - axis[0], p.y - axis[1], p.z - axis[2]),
            (p.x + axis[0], p.y + axis[1], p.z + axis[2]))


@pytest.mark.parametrize("angle_deg", [0.0, 7.5, -11.9])
def test_the_pole_leans_by_the_state_angle_toward_plus_x_from_the_cart_top(angle_deg):
    markers = CartPoleMarkers(POLE_HALF_LENGTH_M, 2.4).update((3, 40), 0.7, angle_deg).markers
    hinge, tip = pole_ends(markers[POLE])
    assert hinge == pytest.approx((0.7, 0.0, CART_SIZE_M[2]), abs=1e-12)
    theta = math.radians(angle_deg)  # positive leans toward +x (the state's convention)
    length = 2 * POLE_HALF_LENGTH_M
    assert tip == pytest.approx((0.7 + length * math.sin(theta), 0.0,
                                 CART_SIZE_M[2] + length * math.cos(theta)), abs=1e-12)
    assert markers[CART].pose.position.x == 0.7
    assert [m.header.stamp for m in markers] == [Time(sec=3, nanosec=40)] * 3


def test_the_serialized_markers_are_rclpys_serialization_of_the_markers():
    from rclpy.serialization import serialize_message
    markers, draw = CartPoleMarkers(POLE_HALF_LENGTH_M, 2.4), random.Random(0)
    for stamp in [(0, 0), (2**31 - 1, 999_999_999)] + [
            (draw.randrange(2**31), draw.randrange(10**9)) for _ in range(200)]:
        x, angle = draw.uniform(-2.4, 2.4), draw.uniform(-12.0, 12.0)
        assert markers.serialized(stamp, x, angle) == serialize_message(
            markers.update(stamp, x, angle))


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(DOMAIN_ID, tmp_path_factory)


def run_all(env, out: Path, *options) -> subprocess.CompletedProcess:
    run = subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--seed", "0",
                          "--trials", "4", "--max-steps", "300", "--out", str(out), *options],
                         cwd=ROOT, env={**env, "CLNN_TEST_RUN": str(out)}, capture_output=True,
                         text=True, timeout=HANG_S)
    assert run.returncode == 0, run.stderr
    return run


def by_topic(bag_dir: Path) -> dict[str, list]:
    """topic (relative) -> its messages decoded by rosbags from the schemas in the bag."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    found = {}
    with AnyReader([bag_dir], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for connection, _, data in reader.messages():
            found.setdefault(names.graph_topic(connection.topic), []).append(
                reader.deserialize(data, connection.msgtype))
    return found


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


@pytest.mark.ros
def test_recorded_markers_show_each_recorded_state(ros_env, tmp_path):
    run_all(ros_env, tmp_path, "--option", "marker_period_ticks=1")  # every tick
    recorded = by_topic(tmp_path / "bag")
    (task,) = recorded[names.TASK]  # latched, recorded once: the order of the values
    assert tuple(task.variable_names) == STATE_NAMES and task.task == "cartpole"
    states = {s.tick: s for s in recorded[names.STATE]}
    arrays = recorded[names.MARKERS]
    assert len(arrays) == len(states) == len(recorded[names.CLOCK])  # one per tick
    for array in arrays:
        track, cart, pole = array.markers
        assert [(m.ns, m.id, m.action, m.header.frame_id) for m in array.markers] == \
            [(NAMESPACE, i, 0, FRAME) for i in (TRACK, CART, POLE)]  # 0: ADD, replacing
        assert (track.type, cart.type, pole.type) == (1, 1, 3)  # CUBE, CUBE, CYLINDER
        assert stamp_ns(track.header) == stamp_ns(cart.header) == stamp_ns(pole.header)
        state = states.pop(stamp_ns(cart.header) // 20_000_000)  # the state of its tick, once
        position, angle = state.values[POSITION], state.values[ANGLE]  # m, deg
        assert cart.pose.position.x == position
        o = pole.pose.orientation  # a turn about y by the pole angle
        assert (o.x, o.z) == (0.0, 0.0)
        assert math.degrees(2 * math.atan2(o.y, o.w)) == pytest.approx(angle, abs=1e-9)
        assert pole_ends(pole)[0] == pytest.approx((position, 0.0, CART_SIZE_M[2]), abs=1e-12)
        assert pole.scale.z == 2 * POLE_HALF_LENGTH_M
    assert not states

    info = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    topics = {t["topic_metadata"]["name"]: t for t in info["rosbag2_bagfile_information"]
              ["topics_with_message_count"]}
    markers = topics[names.absolute(names.MARKERS)]
    assert markers["topic_metadata"]["type"] == names.TOPIC_TYPES[names.MARKERS]
    assert markers["message_count"] == topics[names.absolute(names.STATE)]["message_count"]
    assert markers["topic_metadata"]["offered_qos_profiles"][0]["reliability"] == "reliable"


@pytest.mark.ros
def test_markers_every_kth_tick_decoded_by_mcap_ros2(ros_env, tmp_path):
    """By default (marker_period_ticks 5) markers at ticks 0, 5, 10, ... only. The MarkerArray
    schema in the bag holds its whole definition chain (Marker, Header, Pose, CompressedImage,
    MeshFile, ...), which mcap_ros2 decodes it with."""
    from mcap_ros2.reader import read_ros2_messages
    period = RUN_SETTINGS["marker_period_ticks"]
    assert period > 1
    run_all(ros_env, tmp_path, "--trials", "1")
    path = tmp_path / "bag" / "bag_0.mcap"
    decoded = list(read_ros2_messages(path, topics=[names.absolute(names.MARKERS)]))
    schema = decoded[0].schema.data.decode()
    for dependency in ("visualization_msgs/Marker", "std_msgs/Header", "geometry_msgs/Pose",
                       "sensor_msgs/CompressedImage", "visualization_msgs/MeshFile"):
        assert f"\n{'=' * 80}\nMSG: {dependency}\n" in schema
    states = len(list(read_ros2_messages(path, topics=[names.absolute(names.STATE)])))
    stamps = [m.ros_msg.markers[CART].header.stamp for m in decoded]
    assert [s.sec * 1_000_000_000 + s.nanosec for s in stamps] == \
        [tick * 20_000_000 for tick in range(0, states, period)]
    assert {m.ros_msg.markers[POLE].header.frame_id for m in decoded} == {FRAME}


@pytest.mark.ros
def test_marker_period_0_publishes_no_markers(ros_env, tmp_path):
    run_all(ros_env, tmp_path, "--trials", "1", "--composed", "--option", "marker_period_ticks=0")
    recorded = by_topic(tmp_path / "bag")
    assert set(recorded) == set(names.TOPIC_TYPES) - {names.MARKERS}
    assert len(recorded[names.STATE]) == len(recorded[names.CLOCK]) > 0


@pytest.mark.ros
def test_an_environment_without_markers_runs_and_is_recorded(ros_env, tmp_path):
    """The example node publishes no markers (they are optional in docs/ENV_CONTRACT.md): the
    recorder does not wait for them, and the bag holds the graph's other topics, every tick."""
    run_all(ros_env, tmp_path, "--env-node", "python examples/noisy_cartpole.py")
    recorded = by_topic(tmp_path / "bag")
    assert set(recorded) == set(names.TOPIC_TYPES) - set(names.OPTIONAL)
    ticks = [s.tick for s in recorded[names.STATE]]
    assert ticks == list(range(len(ticks))) and len(recorded[names.CLOCK]) == len(ticks)
