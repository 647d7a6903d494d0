"""The ament_python package clnn_ros, for `colcon build` in a ROS 2 workspace: the code of
../clnn_ros (a link), an executable in lib/clnn_ros for each node and each of the user's
commands, the launch file and the package manifest. pip installs the same code from
../pyproject.toml (its version is package.xml's: tests/test_ros_package.py checks)."""

import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "clnn_ros"
HERE = Path(__file__).resolve().parent
# `ros2 run clnn_ros <executable>`: every node, then the user's commands (pyproject's scripts)
EXECUTABLES = {
    "environment": "clnn_ros.nodes.environment:main",
    "encoder": "clnn_ros.nodes.encoder:main",
    "reward": "clnn_ros.nodes.reward:main",
    "agent": "clnn_ros.nodes.agent:main",
    "trial_manager": "clnn_ros.nodes.trial_manager:main",
    "recorder": "clnn_ros.nodes.recorder:main",
    "run_all": "clnn_ros.run_all:main",
    "echo": "clnn_ros.live.echo:main",
    "topics": "clnn_ros.live.topics:main",
    "analyze": "clnn_ros.analysis.analyze:main",
    "reproduce": "clnn_ros.reproduce.__main__:main",
    "check_env": "clnn_ros.live.check_env:main",
    "save_checkpoint": "clnn_ros.live.save_checkpoint:main",
}

# Each executable is a small script that imports its function from whichever clnn_ros is on the
# Python path. Not a setuptools entry point: its script looks the function up in the metadata of
# the first distribution named clnn_ros, and with pip's copy (no node entry points) found
# before this one's, an executable died with a bare StopIteration.
LAUNCHER = """#!{python}
\"\"\"`ros2 run clnn_ros {name}`: {module}.{function}().\"\"\"
import sys

try:
    from {module} import {function}
except ImportError as error:
    if (error.name or "clnn_ros").partition(".")[0] != "clnn_ros":  # clnn_ros found, not its own
        sys.exit(f"{name}: error: {module} needs the Python package {{error.name!r}}, which is "
                 f"not installed: pip install the packages that the README lists under In a "
                 f"ROS 2 workspace")
    sys.exit(f"{name}: error: cannot import {module} ({{error}}): source the workspace's "
             f"install/setup.bash, or activate the environment that has clnn_ros")
sys.exit({function}())
"""


def launchers(folder: Path) -> list[str]:
    """Write the executables' scripts into `folder` (under this package); their paths, as
    data_files takes them."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, target in EXECUTABLES.items():
        module, function = target.split(":")
        path = folder / name
        path.write_text(LAUNCHER.format(python=sys.executable, name=name, module=module,
                                        function=function))
        path.chmod(0o755)
        paths.append(str(path.relative_to(HERE)))
    return paths


if __name__ == "__main__":
    setup(
        name=PACKAGE,
        version=ElementTree.parse(HERE / "package.xml").findtext("version"),
        packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
        package_data={f"{PACKAGE}.session": ["fastdds_loopback.xml", "fastdds_subnet.xml"]},
        data_files=[
            ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
            (f"share/{PACKAGE}", ["package.xml"]),
            (f"share/{PACKAGE}/launch", ["launch/graph.launch.py"]),
            (f"lib/{PACKAGE}", launchers(HERE / "build" / "launchers")),
        ],
        install_requires=["setuptools"],
        zip_safe=True,
    )
