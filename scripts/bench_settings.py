"""The benchmark's settings (scripts/benchmark_graph.py): run sizes, names in the report, targets,
and the shape of a tick that the raw ring copies from the graph."""

from __future__ import annotations

from pathlib import Path

from clnn_ros.graph.names import GRAPH_NODES, SIM_TIME_NODES

REPO = Path(__file__).resolve().parents[1]
SEED = 1
# Seed 1, 1 SV: a trial is about 270 ticks; 30 trials = 8402 ticks, 8 = 1912, 6 = 1381,
# 5 = 1115, 2 = 302.
FULL = dict(repeats=5, graph_trials={"events": 30, "single": 5},
            ring_ticks={("separate", "events"): 5000, ("composed", "events"): 20000,
                        ("separate", "single"): 1000, ("composed", "single"): 1000},
            profile_trials=8, paced_trials=6)
QUICK = dict(repeats=1, graph_trials={"events": 8, "single": 2},
             ring_ticks={("separate", "events"): 1000, ("composed", "events"): 4000,
                         ("separate", "single"): 500, ("composed", "single"): 500},
             profile_trials=2, paced_trials=2)
RUN_TIMEOUT_S = 120
TEARDOWN_GRACE_S = 10.0  # a ring process still running this long after the result is killed
LAYOUTS = ("separate", "composed")
EXECUTORS = ("events", "single")
EXECUTOR_NAMES = {"events": "EventsExecutor", "single": "SingleThreadedExecutor"}
LAYOUT_NAMES = {"separate": "5 processes", "composed": "composed (1 process)"}
# The graph / raw UInt64 ring targets (EventsExecutor) of the issue "Scale" (a leaner graph).
TARGETS = {"separate": 0.75, "composed": 0.50}
# The runs on Fast DDS's shared memory (the default before 2026-12-05), beside the same on UDP,
# and the share of the shared-memory graph's ticks/s that the UDP graph keeps (issue 35).
SHM = ("graph_shm", "uint64_shm")
UDP_KEEPS = {"separate": 0.95, "composed": 0.95}
# The 50 Hz run: the environment's period, the deadline of the agent's answer, the hogs.
PERIOD_MS = 20.0
DEADLINE_MS = 20.0
PACED_TIMEOUT_S = 180
ROLES = ("environment", "encoder", "reward", "agent", "trial_manager")
# topic: (publishing role, subscribing roles); the graph's clock, env/observation ("state"),
# rln/spikes, rln/reward and rln/action
EDGES = {
    "clock": ("trial_manager", ("environment",)),
    "state": ("environment", ("encoder", "reward", "trial_manager")),
    "spikes": ("encoder", ("agent", "trial_manager")),
    "reward": ("reward", ("agent", "trial_manager")),
    "action": ("agent", ("environment", "trial_manager")),
}
# A role publishes its message number k once it holds message k - lag of each listed topic:
# the environment needs clock(t) and action(t-1); the trial manager publishes clock(t+1) after
# state(t) and action(t) (its clock(0) is the start).
NEEDS = {
    "environment": (("clock", 0), ("action", 1)),
    "encoder": (("state", 0),),
    "reward": (("state", 0),),
    "agent": (("spikes", 0), ("reward", 0)),
    "trial_manager": (("state", 1), ("action", 1)),
}
RING_NS = "/bench_ring"
# The graph's nodes with use_sim_time, whose rclpy TimeSource subscribes /clock as well.
TIME_SOURCES = len(SIM_TIME_NODES)
# The nodes that run on their own time by default; the "sim time everywhere" runs start them
# with -p use_sim_time:=true (every node ran so until 2026-12-03), to measure what it costs.
OWN_TIME_ROLES = tuple(node for node in GRAPH_NODES if node not in SIM_TIME_NODES)
TYPE_NAMES = {"clock": "rosgraph_msgs/Clock", "state": "clnn_ros_msgs/Observation",
              "spikes": "clnn_ros_msgs/SpikeVector", "reward": "clnn_ros_msgs/Reward",
              "action": "clnn_ros_msgs/Action"}
