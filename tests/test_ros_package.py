"""ros_package/, the ament_python package clnn_ros for a ROS 2 workspace: its manifest, its setup
metadata and executables, the launch plan (what graph.launch.py starts, against run_all) and its
supervision (what it does when a node exits), and, where colcon is installed, a `colcon build`
of it and what its install tree holds.

`ros2 launch` itself is not on PyPI: the launch file is only compiled here; tests/test_launch.py
runs it with launch's sources where they are prepared (docs/ROS_GRAPH.md, Under `ros2 launch`)."""

from __future__ import annotations

import ast
import importlib
import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml
from catkin_pkg.package import parse_package

from clnn_ros import run_all
from clnn_ros.processes import launch_plan
from clnn_ros.core.params import ParamError
from clnn_ros.graph.run import node_arguments
from clnn_ros.processes.launch_plan import Step, Supervision

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_DIR = ROOT / "ros_package"
# The ROS packages that are Python modules here but have no share/<name>/package.xml in the venv.
LAUNCH_PACKAGES = {"launch", "launch_ros"}


def setup_distribution():
    """setup.py's metadata, read as colcon reads it (run_setup up to the configuration)."""
    import setuptools  # noqa: F401  (first: distutils is then setuptools' own, as for colcon)
    from distutils.core import run_setup
    cwd = os.getcwd()
    os.chdir(PACKAGE_DIR)
    try:
        return run_setup("setup.py", script_args=["--dry-run"], stop_after="config")
    finally:
        os.chdir(cwd)


def imported_modules(paths) -> set[str]:
    found = set()
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                found.add(node.module.split(".")[0])
    return found


def test_the_manifest_names_the_package_its_version_and_every_ros_package_it_imports():
    package = parse_package(PACKAGE_DIR / "package.xml")
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert (package.name, package.package_format) == ("clnn_ros", 3)
    assert package.version == project["version"]
    assert [e.content for e in package.exports if e.tagname == "build_type"] == ["ament_python"]
    sources = [*(ROOT / "clnn_ros").rglob("*.py"), PACKAGE_DIR / "launch" / "graph.launch.py"]
    ros_packages = {name for name in imported_modules(sources)
                    if (Path(sys.prefix) / "share" / name / "package.xml").is_file()
                    or name in LAUNCH_PACKAGES}
    assert {"rclpy", "clnn_ros_msgs", "std_srvs", "launch_ros"} <= ros_packages
    assert ros_packages <= {d.name for d in package.exec_depends}


def test_setup_installs_the_manifest_marker_launch_file_and_an_executable_per_node():
    distribution = setup_distribution()
    assert distribution.get_name() == "clnn_ros"
    assert distribution.get_version() == parse_package(PACKAGE_DIR / "package.xml").version
    data_files = dict(distribution.data_files)
    executables = data_files.pop("lib/clnn_ros")
    assert data_files == {
        "share/ament_index/resource_index/packages": ["resource/clnn_ros"],
        "share/clnn_ros": ["package.xml"], "share/clnn_ros/launch": ["launch/graph.launch.py"]}
    for _, sources in distribution.data_files:
        assert all((PACKAGE_DIR / source).is_file() for source in sources)
    assert {"clnn_ros", "clnn_ros.nodes", "clnn_ros.core"} <= set(distribution.packages)
    scripts = {}  # executable: "module:function" it runs
    for source in executables:
        path = PACKAGE_DIR / source
        assert os.access(path, os.X_OK), source
        imported = re.search(r"^    from (\S+) import (\w+)$", path.read_text(), re.MULTILINE)
        scripts[path.name] = f"{imported[1]}:{imported[2]}"
    for name, target in scripts.items():
        module, function = target.split(":")
        assert callable(getattr(importlib.import_module(module), function)), name
    # every node module with a main, and every command pip installs (pyproject's scripts)
    nodes = {path.stem for path in (ROOT / "clnn_ros" / "nodes").glob("*.py")
             if "\ndef main(" in path.read_text()}
    assert {scripts[node] for node in nodes} == {f"clnn_ros.nodes.{node}:main" for node in nodes}
    commands = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert set(commands.values()) <= set(scripts.values())
    assert scripts.keys() >= {"environment", "encoder", "agent", "reward", "trial_manager",
                              "recorder", "run_all", "echo", "topics"}


def test_an_executable_missing_a_dependency_names_it_not_the_sourcing(tmp_path):
    """`ros2 run clnn_ros reproduce` where the workspace's pip line had left out matplotlib
    (issue 47): the error blamed sourcing. Now it names the missing package."""
    setup_distribution()  # writes the executables
    (tmp_path / "matplotlib").mkdir()  # first on the path: an import of it fails as if absent
    (tmp_path / "matplotlib" / "__init__.py").write_text(
        "raise ModuleNotFoundError(\"No module named 'matplotlib'\", name='matplotlib')\n")
    run = subprocess.run([sys.executable, str(PACKAGE_DIR / "build" / "launchers" / "reproduce"),
                          "--help"], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(tmp_path)})
    assert run.returncode == 1 and run.stderr.strip().splitlines() == [
        "reproduce: error: clnn_ros.reproduce.__main__ needs the Python package 'matplotlib', "
        "which is not installed: pip install the packages that the README lists under In a "
        "ROS 2 workspace"], run.stderr


def test_the_readmes_workspace_pip_line_installs_every_dependency():
    """The README's pip line for a colcon workspace: every package pyproject.toml needs (it
    left out matplotlib, which package.xml lists: `ros2 run clnn_ros reproduce` failed)."""
    line = next(line for line in (ROOT / "README.md").read_text().splitlines()
                if line.startswith("pip install ") and "pyproject.toml's pins" in line)
    needed = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    given = {re.split(r"[=<>~]", word.strip('"'))[0].lower() for word in line.split()[2:]}
    missing = [d for d in needed if re.split(r"[=<>~]", d)[0].lower() not in given]
    assert not missing, f"the README's pip line lacks {missing}: {line}"


def test_an_executable_without_clnn_ros_on_the_path_says_so_in_one_line():
    """With pip's and colcon's copies both installed and the workspace not sourced, an
    executable looked its function up in the first clnn_ros distribution's metadata (pip's, no
    node entry points) and died with a bare StopIteration. Now it imports the function from
    whichever clnn_ros Python finds, or says in one line what to do."""
    setup_distribution()  # writes the executables
    agent = PACKAGE_DIR / "build" / "launchers" / "agent"
    works = subprocess.run([sys.executable, str(agent), "x"], capture_output=True, text=True,
                           timeout=120)
    assert works.returncode == 2 and works.stderr.startswith(
        "agent: error: unexpected arguments ['x']"), works.stderr
    # -S: no site-packages, so no clnn_ros (nor rclpy) to import
    alone = subprocess.run([sys.executable, "-S", str(agent)], capture_output=True, text=True,
                           timeout=120, cwd="/")
    assert alone.returncode == 1 and "Traceback" not in alone.stderr, alone.stderr
    assert alone.stderr.startswith("agent: error: cannot import clnn_ros.nodes.agent (") and \
        alone.stderr.strip().endswith("source the workspace's install/setup.bash, or activate "
                                      "the environment that has clnn_ros"), alone.stderr
    assert len(alone.stderr.strip().splitlines()) == 1


def test_the_launch_file_compiles():
    path = PACKAGE_DIR / "launch" / "graph.launch.py"
    compile(path.read_text(), str(path), "exec")


def params(path: Path) -> dict:
    return yaml.safe_load(path.read_text())["/**"]["ros__parameters"]


def test_the_launch_plan_is_run_alls_graph_with_its_parameters(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the default bag is bags/run_<UTC time>.mcap under it
    nodes = launch_plan.plan({}, tmp_path)
    assert [n.executable for n in nodes] == ["recorder", *run_all.NODES]
    assert all(n.namespace == "/" and n.remappings == () for n in nodes)
    graph = params(nodes[1].params_file)
    assert graph == {**run_all.build_parameters(run_all.parse_args([])), "out_dir": "",
                     "extra_nodes": "recorder"}
    recorder = params(nodes[0].params_file)
    assert Path(recorder.pop("bag_path")).parent == tmp_path / "bags"
    assert recorder.pop("environment") == "cartpole"  # kept in the bag for analyze's summary
    assert recorder == {k: v for k, v in graph.items() if k != "extra_nodes"}
    assert all(n.params_file == nodes[1].params_file for n in nodes[1:])


def test_launch_arguments_are_run_alls_options(tmp_path):
    """The launch file and run_all make the same run of the same settings, each without the
    other's command line (launch_plan does not go through run_all's argparse)."""
    out = tmp_path / "out"
    params_file = tmp_path / "p.yaml"
    params_file.write_text("/**:\n  ros__parameters:\n    sigma: 4\n")
    arguments = {"seed": "3", "trials": "7", "nsv": "2", "params_file": str(params_file),
                 "namespace": "robot1", "env": "gymnasium", "out": str(out), "record": "false",
                 "stall_timeout": "12.5"}
    nodes = launch_plan.plan(arguments, tmp_path)
    assert [n.executable for n in nodes] == list(run_all.NODES)
    expected = run_all.build_parameters(run_all.parse_args(
        ["--seed", "3", "--trials", "7", "--nsv", "2", "--params-file", str(params_file),
         "--env", "gymnasium", "--stall-timeout", "12.5"]))
    assert params(nodes[0].params_file) == {**expected, "out_dir": str(out.resolve())}
    assert expected["sigma"] == 4 and expected["simulator"] == "gymnasium"
    assert expected["stall_timeout_s"] == 12.5
    for node in nodes:  # the same command-line arguments as run_all gives its processes
        assert ["--ros-args", "--params-file", str(node.params_file), "--log-level",
                node.log_level, "-r", f"__ns:={node.namespace}",
                *[f for rule in node.remappings for f in ("-r", ":=".join(rule))]] == \
            node_arguments(node.params_file, node.namespace)
    acrobot = launch_plan.plan({"env": "gymnasium:Acrobot-v1", "record": "false"}, tmp_path)
    assert params(acrobot[0].params_file)["task"] == "gymnasium:Acrobot-v1"
    assert params(acrobot[0].params_file)["n_actions"] == 3
    external = launch_plan.plan({"env": "external", "record": "false"}, tmp_path)
    assert [n.executable for n in external] == list(run_all.NODES[1:])
    assert params(external[0].params_file)["external_nodes"] == "environment"


@pytest.mark.parametrize("arguments, line", [
    ({"nsv": "two"}, "nsv must be an integer, got 'two'"),
    ({"env": "bullet"}, "env must be one of cartpole, gymnasium, mujoco, external or "
                        "gymnasium:ID, got 'bullet'"),
    ({"env": "gymnasium:Nope-v0"}, "gymnasium:Nope-v0: Environment `Nope` doesn't exist"),
    ({"actions": "-1,1"}, "actions (-1,1) declares the values of a Gymnasium task's Box "
                         "action space"),
    ({"namespace": "1robot"}, "namespace '1robot': expected letters, digits and _"),
    ({"foo": "1"}, "unknown launch argument foo:=1; the arguments: seed, trials, "),
])
def test_bad_launch_arguments_are_one_line(tmp_path, arguments, line):
    with pytest.raises(ParamError) as refused:
        launch_plan.plan(arguments, tmp_path)
    assert str(refused.value).startswith(line)


def test_the_readme_lists_every_launch_argument():
    """rate and protocol were missing there (issue 47)."""
    text = " ".join((ROOT / "README.md").read_text().split())
    listing = text[text.index("The launch arguments are"):][:600]
    assert all(f"`{name}`" in listing for name in (*launch_plan.ARGUMENTS, launch_plan.RECORD)), \
        listing


GRAPH = ["recorder", *run_all.NODES]
END_GRACE_S = launch_plan.SHUTDOWN_GRACE_S + launch_plan.RECORDER_GRACE_S


@pytest.mark.parametrize("exits, steps", [
    ([("encoder", 0), ("trial_manager", 0), ("agent", 0), ("reward", 0), ("environment", 0),
      ("recorder", 0)],  # the episode's end: a node may see EPISODE_END first
     [Step(timer=launch_plan.SHUTDOWN_GRACE_S), Step(timer=END_GRACE_S), Step(), Step(),
      Step(), Step(timer=0.0)]),
    ([("agent", -9)], [Step(fail="node 'agent' died (SIGKILL)")]),
    ([("recorder", 1)], [Step(fail="node 'recorder' exited with status 1")]),
    ([("trial_manager", -15)], [Step(fail="node 'trial_manager' died (SIGTERM)")]),
    # a stall: the trial manager sent EPISODE_END, the recorder finishes the bag, then the failure
    ([("trial_manager", 1), ("agent", 0), ("encoder", 0), ("reward", 0), ("environment", 0),
      ("recorder", 0)],
     [Step(timer=END_GRACE_S), Step(), Step(), Step(), Step(),
      Step(fail="node 'trial_manager' exited with status 1")]),
    # stopped by someone else (exit 0 on SIGTERM), then the trial manager's stall: it is named
    ([("reward", 0), ("trial_manager", 1), ("recorder", 1)],
     [Step(timer=launch_plan.SHUTDOWN_GRACE_S), Step(timer=END_GRACE_S),
      Step(fail="node 'reward' exited with status 0 before the episode ended")]),
])
def test_the_launch_ends_when_the_episode_ends_and_at_once_when_a_node_fails(exits, steps):
    supervision = Supervision(GRAPH)
    assert [supervision.exited(name, code) for name, code in exits] == steps


def test_a_recorder_that_fails_under_launch_gets_the_bag_repair_hint(tmp_path):
    """As run_all's line (issue 37: launch gave none): the unfinished bag and how to save it."""
    bag_path = tmp_path / "bag"
    supervision = Supervision(GRAPH, bag_path)
    assert supervision.exited("recorder", -9) == Step(
        fail=f"node 'recorder' died (SIGKILL); the bag {bag_path} is not finished, its complete "
             f"chunks: python -m clnn_ros.bag repair {bag_path} [--out DIR]")
    assert Supervision(GRAPH, bag_path).exited("agent", -9) == Step(
        fail="node 'agent' died (SIGKILL)")
    planned = launch_plan.plan({"out": str(tmp_path / "out")}, tmp_path)
    assert [node.bag_path for node in planned if node.bag_path] == [tmp_path / "out" / "bag"]


def test_the_launch_ends_a_node_that_does_not_end():
    quit_early = Supervision(GRAPH)
    quit_early.exited("reward", 0)  # and the trial manager waits for it
    assert quit_early.timed_out() == Step(
        fail="node 'reward' exited with status 0 before the episode ended")
    after_the_end = Supervision(GRAPH)
    assert after_the_end.exited("trial_manager", 0) == Step(timer=END_GRACE_S)
    for name in ("agent", "encoder", "reward", "environment"):
        assert after_the_end.exited(name, 0) == Step()
    assert after_the_end.timed_out() == Step(
        stop="recorder still running after the episode ended: stopped")


def colcon() -> str | None:
    """colcon (colcon-common-extensions) from CLNN_COLCON or PATH: it is not in the project's venv
    (its pytest plugins would load into every test run); e.g.
    python3.11 -m venv /tmp/colcon && /tmp/colcon/bin/pip install colcon-common-extensions"""
    return os.environ.get("CLNN_COLCON") or shutil.which("colcon")


@pytest.mark.skipif(colcon() is None, reason="no colcon (set CLNN_COLCON=path/to/colcon)")
def test_colcon_builds_the_package_into_an_install_tree(tmp_path):
    source = tmp_path / "ws" / "src" / "clnn_ros"
    shutil.copytree(ROOT, source, symlinks=True, ignore=shutil.ignore_patterns(
        ".*", "__pycache__", "*.egg-info", "bags", "build", "install", "log"))
    environment = {k: v for k, v in os.environ.items()  # colcon runs its own Python
                   if k not in ("_ROS_WHEELS_BOOTSTRAP_COMPLETE", "LD_LIBRARY_PATH", "PYTHONPATH")}
    workspace = tmp_path / "ws"
    listed = subprocess.run([colcon(), "list"], cwd=workspace, env=environment,
                            capture_output=True, text=True, timeout=300)
    assert listed.returncode == 0, listed.stderr
    assert sorted(line.split("\t")[::2] for line in listed.stdout.splitlines()) == [
        ["clnn_ros", "(ros.ament_python)"], ["clnn_ros_msgs", "(ros.ament_cmake)"]]
    # clnn_ros_msgs is built by scripts/setup.sh into the venv, the underlay here
    built = subprocess.run([colcon(), "build", "--packages-ignore", "clnn_ros_msgs"],
                           cwd=workspace, env=environment, capture_output=True, text=True,
                           timeout=600)
    assert built.returncode == 0, built.stdout + built.stderr
    install = workspace / "install" / "clnn_ros"
    for name in ("environment", "encoder", "reward", "agent", "trial_manager", "recorder",
                 "run_all", "echo", "topics", "analyze", "reproduce", "check_env",
                 "save_checkpoint"):
        assert (install / "lib" / "clnn_ros" / name).is_file(), name
    assert (install / "share" / "clnn_ros" / "package.xml").read_text() == \
        (PACKAGE_DIR / "package.xml").read_text()
    assert (install / "share" / "clnn_ros" / "launch" / "graph.launch.py").is_file()
    assert (install / "share" / "ament_index" / "resource_index" / "packages" / "clnn_ros").is_file()
    site = next((install / "lib").glob("python3*/site-packages"))
    assert (site / "clnn_ros" / "session" / "fastdds_loopback.xml").is_file()
    assert (site / "clnn_ros" / "session" / "fastdds_subnet.xml").is_file()
    # the executables run the installed code (as `ros2 run` would, with this venv's ROS)
    run_env = {**os.environ, "PYTHONPATH": str(site)}
    agent = subprocess.run([sys.executable, str(install / "lib" / "clnn_ros" / "agent"), "x"],
                           cwd=tmp_path, env=run_env, capture_output=True, text=True, timeout=120)
    assert agent.returncode == 2 and agent.stderr.startswith(
        "agent: error: unexpected arguments ['x']"), agent.stderr
    where = subprocess.run([sys.executable, "-c",
                            "import clnn_ros.live.echo; print(clnn_ros.live.echo.__file__)"],
                           cwd=tmp_path, env=run_env, capture_output=True, text=True, timeout=120)
    assert Path(where.stdout.strip()).is_relative_to(site), where.stderr
