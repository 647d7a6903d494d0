"""The graph that `python -m clnn_ros.run_all` starts, one process per node, with its parameters:

    ros2 launch clnn_ros graph.launch.py [seed:=1] [trials:=32] [nsv:=2] [namespace:=robot1]
        [env:=gymnasium|mujoco|external|gymnasium:ID] [actions:=-1,1] [out:=DIR]
        [params_file:=FILE] [record:=false]
        [bag:=DIR] [stall_timeout:=S]

Each argument is run_all's option of the same name (clnn_ros.processes.launch_plan): run_all checks
them
and makes the parameters files, here written into a temporary folder removed at shutdown.

Supervised as run_all supervises its processes (launch_plan.Supervision, on launch's
OnProcessExit): the episode's end (the trial manager exits 0, the others follow) ends the launch
with exit 0; a node that fails (an error status, a signal, or stopped by someone else before the
episode ended) ends it at once with one line naming it, `Caught exception in launch ...: node
'agent' died (SIGKILL)`, and a non-zero exit (launch's LaunchService returns 1 after an
exception). Exits during the launch's own shutdown (Ctrl-C, or after a failure) are expected.
"""

import shutil
import tempfile
from pathlib import Path

from launch import LaunchDescription
from launch.actions import (DeclareLaunchArgument, LogInfo, OpaqueFunction, RegisterEventHandler,
                            Shutdown, TimerAction)
from launch.event_handlers import OnProcessExit, OnShutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from clnn_ros.processes.launch_plan import ARGUMENTS, RECORD, Supervision, plan


class GraphFailed(Exception):
    """A node of the graph failed: raised in the launch's loop, which then shuts down and
    returns 1 (its only way to a non-zero exit); the message is the one line."""


class Supervisor:
    """launch_plan.Supervision's steps carried out with launch's actions."""

    def __init__(self, names, bag_path):
        self.supervision = Supervision(names, bag_path)
        self.timer = None

    def on_exit(self, name):
        def handle(event, context):
            if context.is_shutdown:  # asked to stop: its exit is expected
                return None
            return self.carry_out(self.supervision.exited(name, event.returncode))
        return handle

    def on_timer(self, context):
        if context.is_shutdown:
            return None
        return self.carry_out(self.supervision.timed_out())

    def carry_out(self, step):
        if step.fail:
            raise GraphFailed(step.fail)
        if step.stop:
            return [LogInfo(msg=step.stop), Shutdown(reason=step.stop)]
        if step.timer is None:
            return None
        if self.timer is not None:
            self.timer.cancel()
            self.timer = None
        if step.timer == 0:
            return None
        self.timer = TimerAction(period=step.timer, actions=[OpaqueFunction(
            function=self.on_timer)])
        return [self.timer]


def graph_nodes(context):
    arguments = {name: LaunchConfiguration(name).perform(context) for name in (*ARGUMENTS, RECORD)}
    workdir = Path(tempfile.mkdtemp(prefix="clnn_ros_launch_"))
    try:
        planned = plan(arguments, workdir)
    except BaseException:  # a refused argument (trials:=-3) leaves no directory behind
        shutil.rmtree(workdir, ignore_errors=True)
        raise
    supervisor = Supervisor([node.executable for node in planned],
                            next((node.bag_path for node in planned if node.bag_path), None))
    actions = [RegisterEventHandler(OnShutdown(
        on_shutdown=lambda _event, _context: shutil.rmtree(workdir, ignore_errors=True)))]
    for node in planned:
        action = Node(package="clnn_ros", executable=node.executable,
                      namespace=None if node.namespace == "/" else node.namespace,
                      parameters=[str(node.params_file)], remappings=list(node.remappings),
                      ros_arguments=["--log-level", node.log_level], output="screen")
        actions += [RegisterEventHandler(OnProcessExit(
            target_action=action, on_exit=supervisor.on_exit(node.executable))), action]
    return actions


def generate_launch_description():
    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value="", description=description)
          for name, description in ARGUMENTS.items()),
        DeclareLaunchArgument(RECORD, default_value="true",
                              description="record every topic into a rosbag2 bag directory "
                                          "(run_all --no-record: false)"),
        OpaqueFunction(function=graph_nodes),
    ])
