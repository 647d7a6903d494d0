"""run_all --composed: every node of the graph in this process, on one executor (the recorder
stays a process of its own). The nodes are the same classes that run as processes, given the
run's values in-process instead of a params file."""

from __future__ import annotations

import sys

import rclpy

from ..graph.names import clock_remappings
from ..nodes.agent import AgentNode
from ..nodes.encoder import EncoderNode
from ..nodes.environment import EnvironmentNode
from ..nodes.glue import close_node
from ..nodes.reward import RewardNode
from ..nodes.trial_manager import TrialManagerNode
from ..session.rclpy_session import init_ros, spin_until_finished


def run_composed(values: dict, with_environment: bool, namespace: str,
                 interrupted: list[int]) -> tuple[int, str | None]:
    """Run the episode; returns the trial manager's exit status (or 128 + signal) and its
    reason."""
    classes = [EncoderNode, RewardNode, AgentNode, TrialManagerNode]
    if with_environment:
        classes.insert(0, EnvironmentNode)
    init_ros([sys.argv[0]])
    remaps = [arg for old, new in clock_remappings(namespace) for arg in ("-r", f"{old}:={new}")]
    options = dict(namespace=None if namespace == "/" else namespace,
                   cli_args=["--ros-args", *remaps] if remaps else None)
    nodes = []
    try:
        for cls in classes:
            nodes.append(cls(values, **options))
        manager = nodes[-1]
        spin_until_finished(nodes, manager.finished, interrupted)
        if interrupted:
            manager.interrupted()
            return 128 + interrupted[0], None
        return manager.finished.result(), manager.exit_reason
    finally:
        for node in nodes:
            close_node(node)
        rclpy.try_shutdown()
