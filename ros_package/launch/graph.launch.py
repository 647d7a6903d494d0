"""The graph that `python -m clnn_ros.run_all` starts, one process per node, with its parameters:

    ros2 launch clnn_ros graph.launch.py [seed:=1] [trials:=32] [nsv:=2] [namespace:=robot1]
        [env:=gymnasium|mujoco] [out:=DIR] [params_file:=FILE] [record:=false] [bag:=DIR]

Each argument is run_all's option of the same name (clnn_ros.launch_plan): run_all checks them
and makes the parameters files, here written into a temporary folder removed at shutdown.
"""

import shutil
import tempfile
from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnShutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from clnn_ros.launch_plan import ARGUMENTS, RECORD, plan


def graph_nodes(context):
    workdir = Path(tempfile.mkdtemp(prefix="clnn_ros_launch_"))
    arguments = {name: LaunchConfiguration(name).perform(context) for name in (*ARGUMENTS, RECORD)}
    nodes = [Node(package="clnn_ros", executable=node.executable,
                  namespace=None if node.namespace == "/" else node.namespace,
                  parameters=[str(node.params_file)], remappings=list(node.remappings),
                  ros_arguments=["--log-level", node.log_level], output="screen")
             for node in plan(arguments, workdir)]
    cleanup = RegisterEventHandler(OnShutdown(
        on_shutdown=lambda _event, _context: shutil.rmtree(workdir, ignore_errors=True)))
    return [cleanup, *nodes]


def generate_launch_description():
    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value="", description=description)
          for name, (_, description) in ARGUMENTS.items()),
        DeclareLaunchArgument(RECORD, default_value="true",
                              description="record every topic into a rosbag2 bag directory "
                                          "(run_all --no-record: false)"),
        OpaqueFunction(function=graph_nodes),
    ])
