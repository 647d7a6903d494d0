"""Bad input on every way in: run_all's command line, a parameters YAML (run_all --params-file,
a node's --params-file) and the ROS parameters of a node started by hand. Each gives exactly one
line `<prog>: error: <what is wrong, what is expected>`, a non-zero exit status and no
traceback; run_all fails before it starts anything: no bag, no out dir, no ROS process (rcl
creates ROS_LOG_DIR when a process starts ROS, so that folder must not appear), within a few
CPU seconds (CPU, not wall time: the suite shares a loaded 2-core machine)."""

from __future__ import annotations

import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

from clnn_ros import run_all

from conftest import free_domain_id

DOMAIN_ID = free_domain_id()
FAST_CPU_S = 5.0  # run_all's refusal, interpreter start included (about 0.5 s; a graph: far more)

# Files each case finds in its working directory.
FILES = {
    "file.txt": "a plain file where a directory belongs\n",
    "malformed.yaml": "/**:\n  ros__parameters:\n    sigma: [1,\n",
    "text.yaml": "just text\n",
    "list.yaml": "- sigma: 3\n",
    "no_mapping.yaml": "/**:\n  ros__parameters: 7\n",
    "two_values.yaml": "agent:\n  ros__parameters: {sigma: 128}\n"
                       "encoder:\n  ros__parameters: {sigma: 64, nsv: 1}\n",
}


def params_yaml(name: str, text: str) -> str:
    """A case's parameters YAML: one line `key: value` under `/**: ros__parameters:`."""
    FILES[name] = f"/**:\n  ros__parameters:\n    {text}\n"
    return name


RUN_ALL_CASES = [  # (arguments, what the one error line says)
    # command line: argparse
    (["--seed", "abc"], "argument --seed: invalid int value: 'abc'"),
    (["--unknown-flag"], "unrecognized arguments: --unknown-flag"),
    (["--env", "bullet"], "argument --env: invalid choice: 'bullet'"),
    (["--trials"], "argument --trials: expected one argument"),
    # command line: model parameters
    (["--trials", "0"], "trials must be a positive integer below 2**31, got 0"),
    (["--max-steps", "0"], "max_steps must be a positive integer below 2**31, got 0"),
    (["--nsv", "5"], "nsv must be 1, 2, 3 or 4"),
    (["--state-vars", "pole_angle,pole_tilt"], "state_vars: unknown 'pole_tilt'"),
    (["--nsv", "2", "--state-vars", "pole_angle"], "nsv (2) must be the number of state_vars"),
    (["--physics", "quantum"],
     "physics must be one of 'paper', 'correct', 'integration_slip', 'gymnasium', got 'quantum'"),
    (["--protocol", "gymnasium", "--max-steps", "1000"],
     "protocol gymnasium truncates a trial at 500 steps (CartPole-v1): max_steps must be 500, "
     "got 1000"),
    (["--option", "sigma=-1"], "sigma must be a positive integer below 2**31, got -1"),
    (["--option", "wmax=9"], "unknown parameter 'wmax'; known: angle_edges_deg"),
    (["--option", "sigma"], "--option expects KEY=VALUE, got 'sigma'"),
    (["--option", "sigma=[1,"], "sigma must be an integer, got '[1,'"),
    (["--option", "sigma=[1, 2]"], "sigma must be an integer, got [1, 2]"),
    (["--option", "nsv=true"], "nsv must be an integer, got True"),
    (["--nsv", "2", "--option", "velocity_edge=.nan"], "velocity_edge must be a finite number"),
    (["--option", "w_max=.inf"], "w_max must be a finite number, got inf"),
    (["--option", "pole_mass=0"], "pole_mass must be > 0, got 0.0"),
    (["--option", "angle_edges_deg=[1, 0]"], "angle_edges_deg must be strictly increasing"),
    (["--option", "angle_edges_deg=-20,0"], "angle_edges_deg must lie inside +-angle_limit_deg"),
    (["--option", "w_base=7.999"], "w_base + w_range (8.00681) must not exceed w_max (8)"),
    (["--nsv", "1", "--velocity-edge", "0.3"], "--velocity-edge needs cart_velocity among"),
    (["--nsv", "2", "--velocity-edge", "-1"], "velocity_edge must be > 0, got -1.0"),
    (["--env", "gymnasium", "--option", "tau=0.01"], "--env gymnasium steps gymnasium's tau"),
    (["--env", "mujoco", "--option", "tau=0.01"], "--env mujoco steps mujoco's tau of 0.02 s"),
    # command line: run settings, paths, commands
    (["--seed", "-1"], "seed must be an integer from 0 to 2**32-1, got -1"),
    (["--seed", str(2**32)], "seed must be an integer from 0 to 2**32-1, got 4294967296"),
    (["--stall-timeout", "-1"], "stall_timeout_s must be a finite number > 0, got -1.0"),
    (["--out", "file.txt"], "--out file.txt is a file; expected a directory"),
    (["--out", "file.txt/out"], "file.txt is not a directory"),
    (["--bag", "file.txt/bag"], "file.txt is not a directory"),
    (["--bag", "file.txt"], "--bag file.txt is a file; expected a bag directory"),
    (["--bag", "."], "--bag . holds other files than a bag"),
    (["--bag", "bag", "--no-record"], "--no-record turns off"),
    (["--env-node", ""], "--env-node needs a command"),
    (["--env-node", "no_such_program_clnn"], "--env-node: no program 'no_such_program_clnn'"),
    (["--env-node", "python 'node.py"], "No closing quotation"),
    (["--env-node", "python node.py", "--composed"], "not with --composed"),
    (["--env-node", "."], "--env-node: . is a directory, not a program"),
    (["--env-node", "python ."], "--env-node: . is a directory, not a Python file"),
    # parameters YAML
    (["--params-file", "missing.yaml"], "cannot read params file missing.yaml"),
    (["--params-file", "malformed.yaml"], "params file malformed.yaml is not valid YAML"),
    (["--params-file", "text.yaml"], "must map node names to 'ros__parameters:' mappings"),
    (["--params-file", "list.yaml"], "must map node names to 'ros__parameters:' mappings"),
    (["--params-file", "no_mapping.yaml"], "must map node names to 'ros__parameters:'"),
    (["--params-file", "two_values.yaml"],
     "gives sigma two values (128 for agent, 64 for encoder)"),
    (["--params-file", params_yaml("unknown.yaml", "sigmaa: 3")], "unknown parameter 'sigmaa'"),
    (["--params-file", params_yaml("list_value.yaml", "omega: [1, 2]")],
     "omega must be an integer, got [1, 2]"),
    (["--params-file", params_yaml("bool_int.yaml", "trials: true")],
     "trials must be an integer, got True"),
    (["--params-file", params_yaml("nan.yaml", "gravity: .nan")],
     "gravity must be a finite number, got nan"),
    (["--params-file", params_yaml("text_number.yaml", "cart_mass: heavy")],
     "cart_mass must be a number, got 'heavy'"),
    (["--params-file", params_yaml("segments.yaml", "segments: 257")],
     "segments must be an integer from 1 to 256, got 257"),
    (["--params-file", params_yaml("seed.yaml", "seed: 1.5")],
     "seed must be an integer from 0 to 2**32-1, got 1.5"),
    (["--params-file", params_yaml("extra.yaml", "extra_nodes: viewer")],
     "extra_nodes is set by run_all (--bag / --no-record), not as a parameter"),
    (["--option", "out_dir=/tmp"], "out_dir is set by run_all (--out), not as a parameter"),
    (["--params-file", params_yaml("stall.yaml", "stall_timeout_s: soon")],
     "stall_timeout_s must be a finite number > 0, got 'soon'"),
    (["--params-file", params_yaml("edges.yaml", "angle_edges_deg: [0, 0]")],
     "angle_edges_deg must be strictly increasing, got [0.0, 0.0]"),
    (["--params-file", params_yaml("span.yaml", "angle_span_deg: 13.0")],
     "angle_span_deg (13) must be below angle_limit_deg (12)"),
]
# Through a real run_all process as well (the rest in-process, the same main()).
SUBPROCESS_CASES = {"--seed abc", "--trials 0", "--out file.txt", "--bag file.txt/bag",
                    "--params-file malformed.yaml", "--env-node no_such_program_clnn"}

NODE_CASES = [  # (node, its arguments after --ros-args, what the one error line says)
    ("agent", ["-p", "omega:=-5"], "omega must be a positive integer below 2**31, got -5"),
    ("agent", ["-p", "sigmaa:=3"], "unknown parameter 'sigmaa'"),
    ("agent", ["-p", "segments:=0"], "segments must be an integer from 1 to 256, got 0"),
    ("agent", ["-p", "sigma:=abc"], "sigma must be an integer, got 'abc'"),
    ("agent", ["-p", "sigma"], "Couldn't parse parameter override rule: '-p sigma'"),
    ("agent", ["-p", "seed:=1.5"], "seed must be an integer from 0 to 2**32-1, got 1.5"),
    ("encoder", ["-p", "angle_edges_deg:=[-6,-1.5,0]"], "Sequence should be of same type"),
    ("encoder", ["-p", "nsv:=5"], "nsv must be 1, 2, 3 or 4"),
    ("reward", ["--params-file", "missing.yaml"], "cannot read params file missing.yaml"),
    ("reward", ["--params-file", "malformed.yaml"], "malformed.yaml is not valid YAML"),
    ("reward", ["--params-file", "text.yaml"], "must map node names to 'ros__parameters:'"),
    ("environment", ["--params-file", "unknown.yaml"], "unknown parameter 'sigmaa'"),
    ("environment", ["--params-file", "nan.yaml"], "gravity must be a finite number, got nan"),
    ("encoder", ["--params-file", "two_values.yaml"], "gives sigma two values"),
    ("trial_manager", ["-p", "stall_timeout_s:=0"], "stall_timeout_s must be a finite number > 0"),
    ("trial_manager", ["--unknown-ros-flag"], "unknown ROS arguments ['--unknown-ros-flag']"),
    ("trial_manager", ["--log-level", "loud"], "Couldn't parse log level"),
    ("environment", ["-p", "simulator:=gymnasium", "-p", "tau:=0.01"],
     "tau must be gymnasium's 0.02 s"),
    ("environment", ["-p", "simulator:=mujoco", "-p", "tau:=0.01"], "tau must be MuJoCo's 0.02 s"),
    ("environment", ["-p", "simulator:=bullet"],
     "simulator must be one of cartpole, gymnasium, mujoco, got 'bullet'"),
    # a value the node leaves to others is checked as run_all checks it (issue 37)
    ("environment", ["-p", "trials:=0"], "trials must be a positive integer below 2**31, got 0"),
    ("environment", ["-p", "trials:=99999999999999999999"],
     "trials must be a positive integer below 2**31, got 99999999999999999999"),
    ("encoder", ["-p", "seed:=-1"], "seed must be an integer from 0 to 2**32-1, got -1"),
    ("environment", ["-p", "protocol:=gymnasium"],
     "protocol gymnasium truncates a trial at 500 steps (CartPole-v1): max_steps must be 500"),
    # a renamed node: the graph finds its nodes by name (issue 37: a KeyError before)
    ("agent", ["-r", "__node:=brain"], "the agent node was renamed 'brain': the graph finds"),
    ("encoder", ["-r", "__node:=enc2"], "the encoder node was renamed 'enc2'"),
    ("trial_manager", ["-r", "__node:=tm"], "the trial_manager node was renamed 'tm'"),
    # a params file outside the ROS arguments (here after their end, --): rclpy ignores it
    ("agent", ["--", "--params-file", "nan.yaml"], "unexpected arguments ['--params-file'"),
]


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """The case's working directory with FILES; ROS on this test's domain, logs in
    <workdir>/ros_log (which appears only if some process starts ROS)."""
    for name, text in FILES.items():
        (tmp_path / name).write_text(text)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("ROS_DOMAIN_ID", DOMAIN_ID)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros_log"))
    return tmp_path


def listing(directory: Path) -> list[str]:
    return sorted(str(p.relative_to(directory)) for p in directory.rglob("*"))


def assert_one_error_line(stderr: str, prog: str, message: str) -> None:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith(f"{prog}: error: ") and message in lines[0], lines[0]


def cpu_seconds() -> float:
    """CPU time of this process and of its finished children (run_all and what it started)."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def run_all_in_process(args: list[str], capsys) -> tuple[int, str]:
    """run_all.main's exit status and stderr (argparse's refusal exits via SystemExit)."""
    try:
        status = run_all.main(["--quiet", *args])
    except SystemExit as stop:
        status = stop.code
    return status, capsys.readouterr().err


@pytest.mark.parametrize("args, message", RUN_ALL_CASES,
                         ids=[" ".join(a) for a, _ in RUN_ALL_CASES])
def test_run_all_refuses_bad_input_before_starting_anything(workdir, capsys, args, message):
    before = listing(workdir)
    start = cpu_seconds()
    if " ".join(args) in SUBPROCESS_CASES:
        result = subprocess.run([sys.executable, "-m", "clnn_ros.run_all", "--quiet", *args],
                                capture_output=True, text=True, timeout=30)
        status, stderr = result.returncode, result.stderr
    else:
        status, stderr = run_all_in_process(args, capsys)
    cpu = cpu_seconds() - start
    assert status == 2, stderr
    assert_one_error_line(stderr, "run_all", message)
    assert listing(workdir) == before  # no bag, no out dir, no ROS log: nothing started
    assert cpu < FAST_CPU_S


def test_every_subprocess_case_is_a_case():
    assert SUBPROCESS_CASES <= {" ".join(args) for args, _ in RUN_ALL_CASES}


@pytest.mark.ros
@pytest.mark.parametrize("node, ros_args, message", NODE_CASES,
                         ids=[f"{n} {' '.join(a)}" for n, a, _ in NODE_CASES])
def test_a_node_started_by_hand_refuses_bad_parameters(workdir, node, ros_args, message):
    result = subprocess.run([sys.executable, "-m", f"clnn_ros.nodes.{node}", "--ros-args",
                             *ros_args], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    assert_one_error_line(result.stderr, f"{node}.py", message)


@pytest.mark.parametrize("domain", ["233", "-1", "one"])
@pytest.mark.parametrize("program", [["-m", "clnn_ros.run_all", "--trials", "1"],
                                     ["-m", "clnn_ros.nodes.agent"],
                                     ["-m", "clnn_ros.live.echo", "/rln/spikes"]])
def test_a_domain_id_dds_cannot_use_is_refused_before_ros_starts(workdir, monkeypatch, program,
                                                                  domain):
    """Fast DDS ends a process whose domain has ports past 65535 with status 1 and a line on
    standard output, and rcl takes -1 for the default domain: each program refuses them first."""
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    before = listing(workdir)
    result = subprocess.run([sys.executable, *program], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2 and result.stdout == "", result.stdout
    prog = "run_all" if program[1].endswith("run_all") else program[1].rsplit(".")[-1] + ".py"
    assert_one_error_line(result.stderr, prog,
                          f"ROS_DOMAIN_ID '{domain}' is not a domain: an integer from 0 to 232")
    assert listing(workdir) == before


def test_run_all_hands_the_nodes_checked_values(workdir):
    """A natural YAML list mixing ints and floats, which rcl refuses in a node's parameters,
    reaches the nodes as the floats it was checked as; the params file's values are not
    overwritten by the command line's defaults."""
    (workdir / "mixed.yaml").write_text("/**:\n  ros__parameters:\n    trials: 7\n"
                                        "    stall_timeout_s: 9\n"
                                        "    angle_edges_deg: [-6, -1.5, 0, 1.5, 6]\n")
    values = run_all.build_parameters(run_all.parse_args(["--params-file", "mixed.yaml",
                                                          "--nsv", "2"]))
    assert values["angle_edges_deg"] == [-6.0, -1.5, 0.0, 1.5, 6.0]
    assert all(type(edge) is float for edge in values["angle_edges_deg"])
    assert (values["trials"], values["stall_timeout_s"], values["nsv"]) == (7, 9.0, 2)
