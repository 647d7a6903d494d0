"""`ros2 launch clnn_ros graph.launch.py` with the real launch, launch_ros and ros2launch
(ros2/launch and ros2/launch_ros, jazzy: pure Python, not on PyPI): the episode ends the launch
with exit 0 and its results; a node that fails ends it at once, non-zero, with one line naming
it (a node killed mid-run, a node lost before the first tick); Ctrl-C ends it with no error.

The launch runs as `ros2 launch` runs it (ros2launch.api.launch_a_launch_file on the package's
share/clnn_ros/launch/graph.launch.py), the package found through the ament index in an install
prefix made here as colcon would make it (lib/clnn_ros/<executable>, the package marker, the
launch file). Where launch is not importable from CLNN_ROS_LAUNCH (a folder on PYTHONPATH;
default ../launch_src/site beside the checkout) the tests skip, saying so; docs/ROS_GRAPH.md
(Under `ros2 launch`) says how to make that folder. Fetched code is never part of the repository."""

from __future__ import annotations

import json
import os
import re
import runpy
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from conftest import free_domain_id, ros_environment

pytestmark = pytest.mark.ros  # every test here starts ROS / DDS
ROOT = Path(__file__).resolve().parents[1]
PACKAGE_DIR = ROOT / "ros_package"
LAUNCH_PATH = os.environ.get("CLNN_ROS_LAUNCH", str(ROOT.parent / "launch_src" / "site"))
# What `ros2 launch clnn_ros graph.launch.py ARGS...` does (ros2launch/command/launch.py).
ROS2_LAUNCH = (
    "import sys\n"
    "from ros2launch.api import get_share_file_path_from_package, launch_a_launch_file\n"
    "sys.exit(launch_a_launch_file(launch_file_path=get_share_file_path_from_package(\n"
    "    package_name='clnn_ros', file_name='graph.launch.py'),\n"
    "    launch_file_arguments=sys.argv[1:]))\n")
END_S = 45.0  # a bound against a hang: every launch here ends within seconds of its cause
SUPERVISION = "[ERROR] [clnn_ros]: "  # the supervision's one line
DOMAIN_ID = free_domain_id()


def launch_missing(env: dict) -> str | None:
    probe = subprocess.run([sys.executable, "-c", "import launch, launch_ros, ros2launch.api"],
                           env=env, capture_output=True, text=True, timeout=120)
    if probe.returncode == 0:
        return None
    last = (probe.stderr.strip().splitlines() or ["?"])[-1]
    return f"launch/launch_ros/ros2launch not importable from CLNN_ROS_LAUNCH={LAUNCH_PATH} " \
           f"({last}): docs/ROS_GRAPH.md, 'Under ros2 launch', says how to make it"


def install_prefix(prefix: Path) -> None:
    """The package's install tree as far as `ros2 launch` and launch_ros's Node look: an
    executable per node in lib/clnn_ros (as colcon makes them from setup.py's console scripts,
    running this venv's Python), the ament index's package marker, the launch file."""
    executables = runpy.run_path(str(PACKAGE_DIR / "setup.py"))["EXECUTABLES"]
    lib = prefix / "lib" / "clnn_ros"
    lib.mkdir(parents=True)
    for name, target in executables.items():
        module, function = target.split(":")
        script = lib / name
        script.write_text(f"#!{sys.executable}\nimport sys\nfrom {module} import {function}\n"
                          f"sys.exit({function}())\n")
        script.chmod(0o755)
    index = prefix / "share" / "ament_index" / "resource_index" / "packages"
    index.mkdir(parents=True)
    (index / "clnn_ros").touch()
    launch_dir = prefix / "share" / "clnn_ros" / "launch"
    launch_dir.mkdir(parents=True)
    (launch_dir / "graph.launch.py").symlink_to(PACKAGE_DIR / "launch" / "graph.launch.py")
    (prefix / "share" / "clnn_ros" / "package.xml").symlink_to(PACKAGE_DIR / "package.xml")


@pytest.fixture(scope="module")
def launch_env(tmp_path_factory):
    env = {**ros_environment(DOMAIN_ID, tmp_path_factory),
           "PYTHONPATH": os.pathsep.join(filter(None, [LAUNCH_PATH,
                                                       os.environ.get("PYTHONPATH")]))}
    if reason := launch_missing(env):
        pytest.skip(reason)
    prefix = tmp_path_factory.mktemp("install")
    install_prefix(prefix)
    return {**env, "AMENT_PREFIX_PATH": os.pathsep.join([str(prefix), sys.prefix])}


class Launched:
    """`ros2 launch clnn_ros graph.launch.py ARGS...` running, in a process group of its own
    (as a terminal's foreground job), its output (stdout and stderr) read line by line."""

    def __init__(self, env: dict, tmp_path: Path, *arguments: str):
        self.process = subprocess.Popen(
            [sys.executable, "-c", ROS2_LAUNCH, *arguments],
            env={**env, "CLNN_TEST_RUN": str(tmp_path)}, cwd=tmp_path, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True, start_new_session=True)
        self.lines: list[str] = []
        self.changed = threading.Condition()
        self.reader = threading.Thread(target=self.read, daemon=True)
        self.reader.start()

    def read(self) -> None:
        for line in self.process.stdout:
            with self.changed:
                self.lines.append(line.rstrip("\n"))
                self.changed.notify_all()

    def wait_for(self, pattern: str, timeout: float = 120.0) -> re.Match:
        """The first line matching `pattern`; the timeout bounds a hang, it times nothing."""
        deadline = time.monotonic() + timeout
        with self.changed:
            while True:
                found = next(filter(None, map(re.compile(pattern).search, self.lines)), None)
                if found or time.monotonic() > deadline or not self.reader.is_alive():
                    break
                self.changed.wait(0.2)
        assert found, f"no line matching {pattern!r} within {timeout} s:\n" + self.output()
        return found

    def pid_of(self, node: str) -> int:
        return int(self.wait_for(rf"\[{node}-\d+\]: process started with pid \[(\d+)\]")[1])

    def end(self, timeout: float = END_S) -> int:
        """Its exit status, once it ended by itself (within `timeout`: else the test fails)."""
        try:
            self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            pytest.fail(f"the launch did not end within {timeout} s:\n" + self.output())
        self.reader.join(10.0)
        return self.process.returncode

    def output(self) -> str:
        return "\n".join(self.lines)

    def having(self, text: str) -> list[str]:
        return [line for line in self.lines if text in line]

    def supervision_lines(self) -> list[str]:
        """The supervision's lines, without launch's prefix: "node 'agent' died (SIGKILL)";
        launch's own error lines too (none is expected: "see debug for traceback" misled)."""
        return [line.split(": ", 1)[-1] for line in self.having(SUPERVISION)] + \
            self.having("[ERROR] [launch]")


def test_the_episode_ends_the_launch_with_exit_0_and_its_results(launch_env, tmp_path):
    out = tmp_path / "out"
    launched = Launched(launch_env, tmp_path, "trials:=2", f"out:={out}")
    assert launched.end(120.0) == 0, launched.output()
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["exit_reason"], summary["exit_status"]) == ("completed", 0)
    assert len((out / "trials.csv").read_text().splitlines()) == 1 + 2
    assert (out / "bag" / "metadata.yaml").is_file()
    assert not launched.having(SUPERVISION) and not launched.having("process has died"), \
        launched.output()
    assert len(launched.having("process has finished cleanly")) == 6


@pytest.mark.parametrize("argument, line", [
    ("foo:=1", "graph.launch.py: error: unknown launch argument foo:=1; the arguments: seed, "),
    ("trials:=-3", "graph.launch.py: error: trials must be"),
])
def test_a_bad_launch_argument_is_one_line_and_no_run(launch_env, tmp_path, argument, line):
    """Before (issue 47): foo:=1 ran the whole 20-trial demo and wrote a bag into the current
    directory without a word; a refused value said "see debug for traceback"."""
    launched = Launched(launch_env, tmp_path, argument)
    assert launched.end() == 1, launched.output()
    lines = launched.supervision_lines()
    assert len(lines) == 1 and lines[0].startswith(line), launched.output()
    assert not launched.having("process started") and not launched.having("see debug")
    assert not list(tmp_path.rglob("metadata.yaml"))


def test_max_steps_caps_a_trial(launch_env, tmp_path):
    out = tmp_path / "out"
    launched = Launched(launch_env, tmp_path, "trials:=2", "max_steps:=20", "record:=false",
                        f"out:={out}")  # seed 0's first trials last 32 and 34 steps uncapped
    assert launched.end(120.0) == 0, launched.output()
    rows = (out / "trials.csv").read_text().splitlines()[1:]
    assert [row.split(",")[3:] for row in rows] == [["20", "max_steps"]] * 2, rows


def test_a_node_killed_mid_run_ends_the_launch_at_once_naming_it(launch_env, tmp_path):
    """Before: the launch went on until the trial manager saw the stall, then ended with 0."""
    launched = Launched(launch_env, tmp_path, "trials:=400", "stall_timeout:=30",
                        f"out:={tmp_path / 'out'}")
    agent = launched.pid_of("agent")
    launched.wait_for(r"trial +2/")
    os.kill(agent, signal.SIGKILL)
    killed_at = time.monotonic()
    assert launched.end() != 0, launched.output()
    assert time.monotonic() - killed_at < 25.0  # not after the 30 s stall
    assert launched.supervision_lines() == ["node 'agent' died (SIGKILL)"], launched.output()
    assert not launched.having("see debug for traceback"), launched.output()


def test_a_node_lost_before_the_first_tick_ends_the_launch_naming_it(launch_env, tmp_path):
    """Before: the trial manager waited for it with no end."""
    launched = Launched(launch_env, tmp_path, "trials:=4", "record:=false")
    os.kill(launched.pid_of("encoder"), signal.SIGKILL)
    assert launched.end() != 0, launched.output()
    assert not launched.having("trial    1/")
    assert launched.supervision_lines() == ["node 'encoder' died (SIGKILL)"], launched.output()


def test_a_node_stopped_by_someone_else_ends_the_launch_naming_it(launch_env, tmp_path):
    """SIGTERM from outside the launch: the node exits 0 (a requested shutdown; 143 before
    issue 23's change of the nodes), before the episode ended: within the grace the trial
    manager would have ended, the launch ends, failed, naming it (not after the 30 s stall)."""
    launched = Launched(launch_env, tmp_path, "trials:=400", "stall_timeout:=30",
                        "record:=false")
    reward = launched.pid_of("reward")
    launched.wait_for(r"trial +2/")
    os.kill(reward, signal.SIGTERM)
    stopped_at = time.monotonic()
    assert launched.end() != 0, launched.output()
    assert time.monotonic() - stopped_at < 25.0
    assert launched.supervision_lines() in (
        ["node 'reward' exited with status 0 before the episode ended"],
        ["node 'reward' exited with status 143"]), launched.output()


def test_ctrl_c_ends_the_launch_with_exit_0_and_no_error(launch_env, tmp_path):
    out = tmp_path / "out"
    launched = Launched(launch_env, tmp_path, "trials:=400", f"out:={out}")
    launched.wait_for(r"trial +2/")
    os.killpg(launched.process.pid, signal.SIGINT)  # what a terminal does on Ctrl-C
    assert launched.end() == 0, launched.output()
    assert not launched.having(SUPERVISION), launched.output()
    assert json.loads((out / "summary.json").read_text())["exit_reason"] == "interrupted"
    assert (out / "bag" / "metadata.yaml").is_file()
    died = launched.having("process has died")
    if died and all("exit code 130" in line for line in died):
        pytest.xfail(f"{len(died)} nodes exited 130 (128 + SIGINT) on the launch's Ctrl-C, "
                     f"not 0: the nodes' change of issue 23 is not in yet")
    assert not died, launched.output()
