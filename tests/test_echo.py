"""clnn_ros.live.echo prints as `ros2 topic echo` does (rosidl_runtime_py's message_to_yaml and
message_to_csv: block-style YAML, --flow-style, --csv, `{}` for a message without fields), and
clnn_ros.live.topics --count counts every endpoint of a graph of several participants."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from sensor_msgs.msg import Imu
from std_msgs.msg import Byte, Empty, UInt8MultiArray

from clnn_ros.live.echo import EchoError, get_field, to_csv, to_yaml
from clnn_ros_msgs.msg import Action, InputLabels, Observation, Reward, SpikeVector, TrialEvent

from test_graph import wait_for_line

from conftest import free_domain_id, ros_environment, tool

PROBE = Path(__file__).with_name("probe_participant.py")
SPIKES_FIELDS = "{tick: 7, trial: 1, spikes: [0, 1, 0]}"
SPIKES_BLOCK = "tick: 7\ntrial: 1\nspikes:\n- 0\n- 1\n- 0\n"
SPIKES_FLOW = "{tick: 7, trial: 1, spikes: [0, 1, 0]}\n"
SPIKES_CSV = "7,1,0,1,0"
CLOCK_FIELDS = "{clock: {sec: 3, nanosec: 5}}"  # a nested message
LABELS = InputLabels(labels=["pole_angle[-1,0)deg", "b: c", "x"])


def spikes() -> SpikeVector:
    return SpikeVector(tick=7, trial=1, spikes=[0, 1, 0])


def test_a_message_in_block_flow_and_csv_style():
    assert to_yaml(spikes()) == SPIKES_BLOCK
    assert to_yaml(spikes(), flow_style=True) == SPIKES_FLOW
    assert to_csv(spikes()) == SPIKES_CSV
    assert to_yaml(LABELS) == "labels:\n- pole_angle[-1,0)deg\n- 'b: c'\n- x\n"
    assert to_yaml(LABELS, flow_style=True) == "{labels: ['pole_angle[-1,0)deg', 'b: c', x]}\n"


def test_a_message_without_fields_is_braces_in_yaml_and_an_empty_csv_line():
    assert to_yaml(Empty()) == to_yaml(Empty(), flow_style=True) == "{}\n"
    assert to_csv(Empty()) == ""


def test_scalars_bytes_and_arrays_as_rosidl_runtime_py_writes_them():
    state = Observation(values=[0.0, 0.0, -1.5e-7, 0.0], terminated=True, termination=1)
    assert "\nvalues:\n- 0.0\n- 0.0\n- -1.5e-07\n- 0.0\nreward: 0.0\nterminated: true\n" \
           "truncated: false\ntermination: 1\n" in to_yaml(state)
    assert to_csv(state).endswith(",0.0,0.0,-1.5e-07,0.0,0.0,True,False,1,0")
    reward = Reward(trial_over=True)
    assert "\ntrial_over: true\n" in to_yaml(reward) and to_csv(reward).endswith(",True")
    # a field alone (--field): no YAML end-of-document marker after a scalar
    assert to_yaml(TrialEvent(end_reason="pole_angle").end_reason) == "pole_angle\n"
    assert to_yaml(TrialEvent().end_reason) == "''\n"
    assert to_yaml(spikes().spikes) == "- 0\n- 1\n- 0\n" and to_csv(spikes().spikes) == "0,1,0"
    assert to_yaml(Byte(data=b"A")) == "data: A\n" and to_csv(Byte(data=b"A")) == "b'A'"
    imu = Imu()  # a fixed-size array is a numpy array
    imu.orientation_covariance[0] = 0.5
    assert to_yaml(imu.orientation_covariance, flow_style=True) == f"[0.5{', 0.0' * 8}]\n"
    assert to_csv(imu.orientation_covariance) == "0.5" + ",0.0" * 8
    assert to_csv(UInt8MultiArray(data=[1, 2])) == ",0,1,2"  # layout.dim is empty


def test_a_field_by_name_and_an_element_by_its_index():
    """--field values[2]: one of an observation's values (the cart-pole's pole angle); a name
    or an index the message does not have is one error line (before any message comes only
    the names can be checked: its sequences are empty)."""
    state = Observation(values=[0.5, 0.0, -1.5e-7, 3.0])
    assert to_yaml(get_field(state, "values[2]")) == "-1.5e-07\n"
    assert to_csv(get_field(state, "values")) == "0.5,0.0,-1.5e-07,3.0"
    assert get_field(Action(action=1), "action") == 1
    assert get_field(Observation(), "values[7]", indexed=False) is not None  # names alone
    for path, message in (("values[4]", "no element 4 in --field values[4]: 'values' has 4 "
                                        "elements"),
                          ("value", "no field 'value' in --field value (fields there: tick, "
                                    "trial, values, reward,"),
                          ("reward[0]", "'reward' in --field reward[0] is not a sequence")):
        with pytest.raises(EchoError, match=re.escape(message)):
            get_field(state, path)


@pytest.mark.parametrize("options, error", [
    (["--csv", "--flow-style"], "echo: error: argument --flow-style: not allowed with argument --csv"),
    (["--raster", "--field", "tick"], "echo: error: --raster prints whole SpikeVectors: not with --field"),
])
def test_options_that_do_not_go_together(options, error):
    run = subprocess.run([sys.executable, "-m", "clnn_ros.live.echo", "/rln/spikes", *options],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and run.stderr == error + "\n"


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return ros_environment(free_domain_id(), tmp_path_factory)


def start_probe(env, topic: str, type_name: str, fields: str, nodes: int = 1):
    probe = subprocess.Popen([sys.executable, str(PROBE), topic, type_name, fields, str(nodes)],
                             env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    wait_for_line(probe.stdout, "ready")
    return probe


def stop(probes) -> None:
    for probe in probes:
        probe.stdin.close()  # it exits when its standard input closes
    for probe in probes:
        try:
            probe.wait(timeout=30)
        except subprocess.TimeoutExpired:
            probe.kill()
            probe.wait()


def echo_once(env, topic, *options) -> str:
    # not one of the graph's topics: it must be discovered (a generous bound on a loaded machine)
    run = tool(env, "clnn_ros.live.echo", topic, "--once", "--wait", "60", *options)
    assert run.returncode == 0 and run.stderr == "", run.stderr
    return run.stdout


TERMINAL_COLOR = re.compile(r"\x1b\[[\d;]*m")


@pytest.mark.ros
def test_fast_dds_logs_to_standard_error_not_standard_output(tmp_path):
    """Standard output is a tool's (fastdds_loopback.xml): Fast DDS's Error for a domain whose
    ports pass 65535, got by a process without the tools' check of ROS_DOMAIN_ID, goes to
    standard error (Fast DDS then ends the process, with a plain line of its own on stdout)."""
    create_a_node = "import clnn_ros.session.rosenv, rclpy; rclpy.init(); rclpy.create_node('n')"
    run = subprocess.run([sys.executable, "-c", create_a_node],
                         capture_output=True, text=True,
                         env={**os.environ, "ROS_DOMAIN_ID": "233", "ROS_LOG_DIR": str(tmp_path)},
                         timeout=120)
    logged = "[RTPS Error] Calculated port number is too high."
    assert run.returncode == 1 and logged in TERMINAL_COLOR.sub("", run.stderr), run.stderr
    assert logged not in TERMINAL_COLOR.sub("", run.stdout), run.stdout


@pytest.mark.ros
def test_echo_a_live_topic_in_each_style(ros_env):
    probes = [start_probe(ros_env, "/probe/spikes", "clnn_ros_msgs/msg/SpikeVector", SPIKES_FIELDS),
              start_probe(ros_env, "/probe/empty", "std_msgs/msg/Empty", "{}"),
              start_probe(ros_env, "/probe/clock", "rosgraph_msgs/msg/Clock", CLOCK_FIELDS)]
    try:
        assert echo_once(ros_env, "/probe/spikes") == SPIKES_BLOCK + "---\n"
        assert echo_once(ros_env, "/probe/spikes", "--flow-style") == SPIKES_FLOW + "---\n"
        assert echo_once(ros_env, "/probe/spikes", "--csv") == SPIKES_CSV + "\n"
        assert echo_once(ros_env, "/probe/clock", "--field", "clock") == \
            "sec: 3\nnanosec: 5\n---\n"
        assert echo_once(ros_env, "/probe/clock", "--field", "clock.nanosec") == "5\n---\n"
        assert echo_once(ros_env, "/probe/clock", "--field", "clock", "--flow-style") \
            == "{sec: 3, nanosec: 5}\n---\n"
        assert echo_once(ros_env, "/probe/spikes", "--field", "spikes", "--csv") == "0,1,0\n"
        assert echo_once(ros_env, "/probe/spikes", "--field", "tick") == "7\n---\n"
        assert echo_once(ros_env, "/probe/empty") == "{}\n---\n"
        assert echo_once(ros_env, "/probe/empty", "--csv") == "\n"
    finally:
        stop(probes)


@pytest.mark.ros
def test_topics_counts_every_endpoint_of_several_participants(ros_env):
    """Three processes (participants) of two nodes each: the counts are complete in one call
    (the tool waits until discovery is complete and settled), and its own endpoints (it has a
    /parameter_events publisher) are not counted."""
    probes = [start_probe(ros_env, "/probe/counted", "std_msgs/msg/Empty", "{}", nodes=2)
              for _ in range(3)]
    try:
        listed = tool(ros_env, "clnn_ros.live.topics", "--count")
        assert listed.returncode == 0 and listed.stderr == "", listed.stderr
        assert listed.stdout.splitlines() == [
            "/parameter_events [rcl_interfaces/msg/ParameterEvent]  publishers 6, subscribers 0",
            "/probe/counted [std_msgs/msg/Empty]  publishers 6, subscribers 6",
            "/rosout [rcl_interfaces/msg/Log]  publishers 6, subscribers 0"]
    finally:
        stop(probes)
