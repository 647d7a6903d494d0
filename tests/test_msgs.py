"""The interface package clnn_ros_msgs (msgs_spec/, built into .venv by scripts/setup.sh):
it imports, its messages serialize, and they round-trip through real DDS publishers and
subscribers, in one process and across two processes.

Isolation: discovery on loopback, a private ROS_DOMAIN_ID, ROS logs in a temp dir.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import rclpy

from conftest import free_domain_id
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message

from clnn_ros_msgs.msg import (
    Action,
    InputLabels,
    Observation,
    Reward,
    SpikeVector,
    TaskDescription,
    TrialEvent,
    WeightSnapshot,
)

from clnn_ros.graph import fields as message_fields
from clnn_ros.core.params import Params
from clnn_ros.core.physics import CONTINUE, FAIL_ANGLE, FAIL_POSITION
from clnn_ros.core.task import cartpole_task
from clnn_ros.graph.names import ENV_CONTRACT_VERSION
from clnn_ros.graph.task_description import Described, described
from clnn_ros.tasks.cartpole import TERMINATIONS

pytestmark = pytest.mark.ros  # every test here starts ROS / DDS
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.VOLATILE)
# Domains 0..232 work with Fast DDS; keep this module's in its own slice of them.
DOMAIN_ID = int(free_domain_id())


@pytest.fixture(scope="module", autouse=True)
def ros_env(tmp_path_factory):
    """Loopback discovery, private domain, logs in a temp dir; restored afterwards."""
    saved = {k: os.environ.get(k) for k in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID", "ROS_LOG_DIR")}
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ["ROS_DOMAIN_ID"] = str(DOMAIN_ID)
    os.environ["ROS_LOG_DIR"] = str(tmp_path_factory.mktemp("ros_log"))
    yield
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


@pytest.fixture
def context():
    """A private rclpy context (not the global one), shut down afterwards."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    try:
        yield ctx
    finally:
        if ctx.ok():
            rclpy.shutdown(context=ctx)


def sample_messages() -> list:
    """One message of each type with every field set to a non-default value."""
    tick, trial = 12345678901, 7
    msgs = [
        Observation(tick=tick, trial=trial, values=[-0.25, 0.5, -12.5, 3.75], reward=-1.5,
                    terminated=True, truncated=False, termination=1, successful_steps=9999),
        TaskDescription(**{**cartpole_description().fields(),  # NaN would not compare equal
                           "reward_threshold": 475.0}),
        SpikeVector(tick=tick, trial=trial, spikes=[0, 0, 1, 0, 0, 0, 0, 1, 0]),
        Action(tick=tick, trial=trial, action=1, winning_segment=5),
        Reward(tick=tick, trial=trial, reward_one_hot=[0, 1], success_counter=42),
        TrialEvent(tick=tick, trial=trial, event=TrialEvent.END, initial_angle_deg=-1.5,
                   successful_steps=10000, end_reason="cart_position", seed=4294967295),
        WeightSnapshot(tick=tick, trial=trial, neurons=2, segments=3, inputs=9,
                       weights=[0.001 * k for k in range(2 * 3 * 9)]),
    ]
    return msgs


def cartpole_description() -> Described:
    """The paper's cart-pole as its environment node describes it (limits as bounds)."""
    return Described(cartpole_task(Params(max_steps=2000)), TERMINATIONS)


def as_dict(msg) -> dict:
    """Field values as plain Python (sequences as lists, nested messages recursively)."""
    out = {}
    for name in msg.get_fields_and_field_types():
        v = getattr(msg, name)
        if hasattr(v, "get_fields_and_field_types"):
            v = as_dict(v)
        elif not isinstance(v, (str, bytes, bool, int, float)):
            v = [x.item() if hasattr(x, "item") else x for x in v]
        out[name] = v
    return out


def test_definitions():
    """Field names and types, and the constants, are the documented ones."""
    common = {"tick": "uint64", "trial": "uint32"}  # no Header: the tick is the time
    expected = {
        Observation: {"values": "sequence<double>", "reward": "double", "terminated": "boolean",
                      "truncated": "boolean", "termination": "uint8",
                      "successful_steps": "uint32"},
        SpikeVector: {"spikes": "sequence<uint8>"},
        Action: {"action": "uint8", "winning_segment": "uint8"},
        Reward: {"reward_one_hot": "uint8[2]", "success_counter": "uint32",
                 "trial_over": "boolean"},
        TrialEvent: {"event": "uint8", "initial_angle_deg": "double", "successful_steps": "uint32",
                     "end_reason": "string", "seed": "uint32"},
        WeightSnapshot: {"neurons": "uint16", "segments": "uint16", "inputs": "uint16",
                         "weights": "sequence<double>"},
    }
    for cls, fields in expected.items():
        assert cls.get_fields_and_field_types() == {**common, **fields}, cls.__name__
    # once per run, not per tick: no tick or trial
    assert InputLabels.get_fields_and_field_types() == {"labels": "sequence<string>"}
    assert TaskDescription.get_fields_and_field_types() == {
        "contract_version": "uint16", "task": "string",
        "variable_names": "sequence<string>", "variable_units": "sequence<string>",
        "variable_low": "sequence<double>", "variable_high": "sequence<double>",
        "action_labels": "sequence<string>", "action_values": "sequence<double>",
        "max_steps": "uint32", "reward_threshold": "double", "ends_in": "string",
        "termination_reasons": "sequence<string>"}
    assert (TrialEvent.START, TrialEvent.END, TrialEvent.EPISODE_END) == (0, 1, 2) == \
        (message_fields.START, message_fields.END, message_fields.EPISODE_END)
    # a trial's last tick: no action applies
    assert Action.ACTION_NONE == message_fields.ACTION_NONE == 255
    # the cart-pole's termination is the physics status: 1 + an index of its reasons, as
    # trials.csv names them; CONTINUE (0) none
    reasons = message_fields.CARTPOLE_TERMINATIONS
    assert reasons == TERMINATIONS == ("pole_angle", "cart_position")
    assert (CONTINUE, FAIL_ANGLE, FAIL_POSITION) == (0, 1 + reasons.index("pole_angle"),
                                                     1 + reasons.index("cart_position"))
    assert message_fields.END_REASONS == (message_fields.REACHED_MAX_STEPS, *reasons)
    assert Observation().termination == CONTINUE and not Observation().terminated
    assert list(Reward().reward_one_hot) == [0, 0]


def test_a_task_description_round_trips_to_the_task():
    """The cart-pole's description, serialized and read back (graph.task_description), is the
    task it was made of: names, units, bounds, actions, truncation, its reasons."""
    made = cartpole_description()
    msg = deserialize_message(serialize_message(TaskDescription(**made.fields())),
                              TaskDescription)
    assert msg.contract_version == ENV_CONTRACT_VERSION == 4
    assert list(msg.variable_names) == ["cart_position", "cart_velocity", "pole_angle",
                                        "pole_angular_velocity"]
    assert list(msg.variable_units) == ["m", "m/s", "deg", "deg/s"]
    assert list(msg.action_labels) == ["-F", "+F"]  # action 0 pushes with -F, 1 with +F
    back = described(msg)
    assert back == made
    assert [back.end_reason(k) for k in (FAIL_ANGLE, FAIL_POSITION)] == list(TERMINATIONS)


def test_type_description_files_installed():
    """The .msg and the type-hash .json that MCAP/rosbag2 writers need are installed in the venv."""
    share = Path(sys.prefix) / "share" / "clnn_ros_msgs" / "msg"
    for cls in (Observation, TaskDescription, SpikeVector, Action, Reward, TrialEvent,
                WeightSnapshot):
        assert (share / f"{cls.__name__}.msg").is_file()
        assert (share / f"{cls.__name__}.json").is_file()


def test_cdr_round_trip():
    for m in sample_messages():
        back = deserialize_message(serialize_message(m), type(m))
        assert as_dict(back) == as_dict(m), type(m).__name__


def wait_for(pred, executor, timeout=10.0) -> bool:
    end = time.monotonic() + timeout
    while not pred() and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.02)
    return pred()


def test_pub_sub_round_trip_in_process(context):
    """Every message type from a publisher node to a subscriber node through Fast DDS."""
    pub_node = rclpy.create_node("clnn_msgs_test_pub", context=context)
    sub_node = rclpy.create_node("clnn_msgs_test_sub", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(pub_node)
    executor.add_node(sub_node)
    try:
        sent = sample_messages()
        received: dict[str, list] = {}
        pubs = []
        for m in sent:
            topic = f"clnn_test/{type(m).__name__}"
            pubs.append(pub_node.create_publisher(type(m), topic, QOS))
            sub_node.create_subscription(type(m), topic,
                                         lambda msg, k=topic: received.setdefault(k, []).append(msg), QOS)
        assert wait_for(lambda: all(p.get_subscription_count() >= 1 for p in pubs), executor), \
            "subscriptions did not match"
        for p, m in zip(pubs, sent):
            p.publish(m)
        assert wait_for(lambda: len(received) == len(sent), executor), f"received only {sorted(received)}"
        for m in sent:
            got = received[f"clnn_test/{type(m).__name__}"]
            assert len(got) == 1
            assert as_dict(got[0]) == as_dict(m), type(m).__name__
    finally:
        executor.shutdown()
        pub_node.destroy_node()
        sub_node.destroy_node()


PUBLISHER = textwrap.dedent("""
    import sys, time, rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from clnn_ros_msgs.msg import SpikeVector
    rclpy.init(domain_id=int(sys.argv[1]))
    node = rclpy.create_node("clnn_msgs_test_remote_pub")
    pub = node.create_publisher(SpikeVector, "clnn_test/remote_spikes",
                                QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    end = time.monotonic() + 20
    while pub.get_subscription_count() < 1 and time.monotonic() < end:
        time.sleep(0.02)
    m = SpikeVector(tick=3, trial=1, spikes=[0, 1, 0, 0, 0, 0])
    pub.publish(m)
    time.sleep(1.0)  # let RELIABLE delivery finish before the writer goes away
    node.destroy_node()
    rclpy.shutdown()
""")


def test_pub_sub_across_processes(context):
    """A SpikeVector from a publisher in another process (same venv python)."""
    node = rclpy.create_node("clnn_msgs_test_remote_sub", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    got = []
    node.create_subscription(SpikeVector, "clnn_test/remote_spikes", got.append, QOS)
    proc = subprocess.Popen([sys.executable, "-c", PUBLISHER, str(DOMAIN_ID)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        ok = wait_for(lambda: len(got) >= 1, executor, timeout=30.0)
        out, _ = proc.communicate(timeout=30)
        assert ok, f"nothing received; publisher said:\n{out}"
        assert proc.returncode == 0, out
        m = got[0]
        assert (m.tick, m.trial, list(m.spikes)) == (3, 1, [0, 1, 0, 0, 0, 0])
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        executor.shutdown()
        node.destroy_node()
