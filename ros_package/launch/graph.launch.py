"""The graph that `python -m clnn_ros.run_all` starts, one process per node, with its parameters:

    ros2 launch clnn_ros graph.launch.py [seed:=1] [trials:=32] [nsv:=2] [namespace:=robot1]
        [state_vars:=pole_angle,cart_position] [max_steps:=N] [rate:=50] [protocol:=gymnasium]
        [env:=gymnasium|mujoco|external|gymnasium:ID] [actions:=-1,1] [out:=DIR]
        [params_file:=FILE] [record:=false] [bag:=DIR] [stall_timeout:=S]

Each argument is run_all's option of the same name (clnn_ros.processes.launch_plan): run_all checks
them and makes the parameters files, here written into a temporary folder removed at shutdown. An
argument not declared here is refused in one line, before any node starts (launch itself keeps
any `name:=value`).

Supervised as run_all supervises its processes (launch_plan.Supervision, on launch's
OnProcessExit): the episode's end (the trial manager exits 0, the others follow) ends the launch
with exit 0; a node that fails (an error status, a signal, or stopped by someone else before the
episode ended) ends it at once with one line naming it, `[ERROR] [clnn_ros]: node 'agent' died
(SIGKILL)`, and exit status 1 (failed). Exits during the launch's own shutdown (Ctrl-C, or after
a failure) are expected.
"""

import asyncio
import logging
import shutil
import tempfile
from pathlib import Path

import launch.logging
from launch import LaunchDescription
from launch.actions import (DeclareLaunchArgument, LogInfo, OpaqueFunction, RegisterEventHandler,
                            Shutdown, TimerAction)
from launch.event_handlers import OnProcessExit, OnShutdown
from launch_ros.actions import Node

from clnn_ros.core.params import ParamError
from clnn_ros.processes.launch_plan import ARGUMENTS, LAUNCH_OWN, RECORD, Supervision, plan


def failed(line):
    """End the launch with `line` as its one error line and exit status 1. launch returns 1 only
    after an error in its loop: an exception it reports as "Caught exception in launch (see
    debug for traceback)", though there is none, or a call of the loop's exception handler
    (launch's sets the status, then asyncio logs the message: that copy of our line is
    dropped)."""
    launch.logging.get_logger("clnn_ros").error(line)
    logging.getLogger("asyncio").addFilter(lambda record: record.getMessage() != line)
    asyncio.get_event_loop().call_exception_handler({"message": line})
    return [Shutdown(reason=line)]


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
            return failed(step.fail)
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
    # every `name:=value` given (launch keeps undeclared ones too): plan refuses the unknown
    arguments = {name: value for name, value in context.launch_configurations.items()
                 if name not in LAUNCH_OWN}
    workdir = Path(tempfile.mkdtemp(prefix="clnn_ros_launch_"))
    try:
        planned = plan(arguments, workdir)
    except ParamError as error:  # a refused argument (trials:=-3): no node, no directory
        shutil.rmtree(workdir, ignore_errors=True)
        return failed(f"graph.launch.py: error: {error}")
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
