"""The graph's nodes as the benchmark runs them (scripts/benchmark_graph.py): the project's node
classes, measured through their public attributes, so that the nodes themselves run unchanged.

    python scripts/bench_node.py ROLE [--ticks-file F] [--profile F] --ros-args ...
        one node process, as `python -m clnn_ros.nodes.ROLE` (clnn_ros.nodes.glue.run_node);
    python scripts/bench_node.py composed --values F [--ticks-file F] [--profile F]
                                 [--sim-time-everywhere]
        the five nodes on one executor, as `run_all --composed`, given the run's values (JSON);
        --sim-time-everywhere: the nodes that run on their own time by default (OWN_TIME_ROLES)
        with use_sim_time true, as a node process gets it from -p use_sim_time:=true.

--ticks-file (the trial manager): when it publishes each clock(t) (its clock_pub) and when its
TickJoin holds state(t) and action(t) (its join's completion, before on_tick), written as
{"published": [ns...], "completed": [ns...]} (time.perf_counter_ns) at the end.
--profile: cProfile into F. A node process: with a CPU-time timer, from its first lockstep
publication to its end. Composed: with the wall clock, from the trial manager's advance(0)
to its stop().
"""

from __future__ import annotations

import argparse
import cProfile
import json
import sys
import time
from pathlib import Path
from typing import Callable

from bench_settings import OWN_TIME_ROLES

# The lockstep output of each node: its first publication starts a node process's profile.
OUTPUTS = {"environment": "state_pub", "encoder": "spikes_pub", "reward": "reward_pub",
           "agent": "action_pub", "trial_manager": "clock_pub"}
ROLES = tuple(OUTPUTS)


class Publishing:
    """A node's publisher that calls `before(msg)` before each publication."""

    def __init__(self, publisher, before: Callable[[object], None]):
        self.publisher, self.before = publisher, before

    def publish(self, msg) -> None:
        self.before(msg)
        self.publisher.publish(msg)

    def __getattr__(self, name):  # the publisher's other methods (matching, acks)
        return getattr(self.publisher, name)


class TickTimes:
    """The trial manager's clock(t) publications and tick completions, timed."""

    def __init__(self, manager):
        self.published, self.completed = [], []
        manager.clock_pub = Publishing(
            manager.clock_pub, lambda _msg: self.published.append(time.perf_counter_ns()))
        complete = manager.join.complete

        def timed_complete(inbox: dict) -> None:
            self.completed.append(time.perf_counter_ns())
            complete(inbox)
        manager.join.complete = timed_complete

    def write(self, path: Path) -> None:
        path.write_text(json.dumps({"published": self.published, "completed": self.completed}))


def node_class(role: str):
    from clnn_ros.nodes.agent import AgentNode
    from clnn_ros.nodes.encoder import EncoderNode
    from clnn_ros.nodes.environment import EnvironmentNode
    from clnn_ros.nodes.reward import RewardNode
    from clnn_ros.nodes.trial_manager import TrialManagerNode
    return {"environment": EnvironmentNode, "encoder": EncoderNode, "reward": RewardNode,
            "agent": AgentNode, "trial_manager": TrialManagerNode}[role]


def profile_from_first_output(node, role: str, profile: cProfile.Profile) -> None:
    output = getattr(node, OUTPUTS[role])

    def start(_msg) -> None:
        profile.enable()
        setattr(node, OUTPUTS[role], output)  # profiled from here on: no more wrapper
    setattr(node, OUTPUTS[role], Publishing(output, start))


def run_process(role: str, ticks_file: Path | None, profile_file: Path | None,
                ros_argv: list[str]) -> int:
    from clnn_ros.nodes.glue import run_node

    cls = node_class(role)
    profile = cProfile.Profile(time.thread_time) if profile_file else None
    made = []

    def make_node(run: dict):
        node = cls(run)
        made.append((node, TickTimes(node) if ticks_file else None))
        if profile is not None:
            profile_from_first_output(node, role, profile)
        return node

    status = run_node(make_node, [sys.argv[0], *ros_argv],
                      getattr(cls, "interrupted", None))
    if profile is not None:
        profile.disable()
        profile.dump_stats(str(profile_file))
    if made and made[0][1] is not None:
        made[0][1].write(ticks_file)
    return status


def run_composed(values: dict, ticks_file: Path | None, profile_file: Path | None,
                 sim_time_everywhere: bool = False) -> int:
    from rclpy.parameter import Parameter

    from clnn_ros.nodes.glue import close_node
    from clnn_ros.session.rclpy_session import ros_session, spin_until_finished

    sim_time = dict(parameter_overrides=[Parameter("use_sim_time", value=True)])

    with ros_session([sys.argv[0]]) as signals:
        nodes = []
        try:
            for role in ("environment", "encoder", "reward", "agent", "trial_manager"):
                nodes.append(node_class(role)(values, **(
                    sim_time if sim_time_everywhere and role in OWN_TIME_ROLES else {})))
            manager = nodes[-1]
            times = TickTimes(manager) if ticks_file else None
            if profile_file:
                profile_composed(manager, profile_file)
            spin_until_finished(nodes, manager.finished, signals)
            if signals:
                return 128 + signals[0]
            if times is not None:
                times.write(ticks_file)
            return manager.finished.result()
        finally:
            for node in nodes:
                close_node(node)


def profile_composed(manager, profile_file: Path) -> None:
    """Profile from the trial manager's first clock to its stop (the episode, not the start-up
    and discovery before it nor the teardown after it)."""
    profile = cProfile.Profile()
    advance, stop = manager.advance, manager.stop

    def profiled_advance(tick: int, starts_trial: bool) -> None:
        if tick == 0:
            profile.enable()
        advance(tick, starts_trial)

    def profiled_stop(*args, **kwargs) -> None:
        profile.disable()
        stop(*args, **kwargs)
        profile.dump_stats(str(profile_file))
    manager.advance, manager.stop = profiled_advance, profiled_stop


def main(argv: list[str]) -> int:
    split = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    parser = argparse.ArgumentParser(prog="bench_node.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("role", choices=(*ROLES, "composed"))
    parser.add_argument("--ticks-file", type=Path)
    parser.add_argument("--profile", type=Path)
    parser.add_argument("--values", type=Path, help="composed: the run's values (JSON)")
    parser.add_argument("--sim-time-everywhere", action="store_true",
                        help="composed: OWN_TIME_ROLES with use_sim_time true as well")
    a = parser.parse_args(argv[:split])
    if a.role == "composed":
        return run_composed(json.loads(a.values.read_text()), a.ticks_file, a.profile,
                            a.sim_time_everywhere)
    return run_process(a.role, a.ticks_file, a.profile, argv[split:])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
