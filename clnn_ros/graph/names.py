"""Names of the graph: its nodes, topics and run settings. No ROS import, so offline tools (bag, analyze) read
them without loading rclpy.

Topic names are relative: a node resolves them in its namespace, so `-r __ns:=/robot1` (or
run_all --namespace robot1) moves the whole graph to /robot1/... Names whose first token starts
with `_` are plumbing, hidden by ROS's convention (`ros2 topic list` shows them only with
--include-hidden-topics).

Lockstep protocol (one tick = one physics step tau of sim time; every message carries the tick):

    trial_manager --clock(t) [+ trial/event START(t)]--> environment
    environment   --cartpole/state(t)--> encoder, reward, trial_manager
                  [--cartpole/markers(t)--> a 3D view (Foxglove, RViz), the recorder, at ticks
                   that are multiples of marker_period_ticks: no node of the graph reads it]
    encoder       --rln/spikes(t)--> agent            reward --rln/reward(t)--> agent
    agent         --rln/action(t)--> environment (applied at tick t+1), trial_manager
    trial_manager, holding state(t) and action(t), publishes clock(t+1)
"""

CLOCK = "clock"
TRIAL_EVENT = "trial/event"
STATE = "cartpole/state"
MARKERS = "cartpole/markers"
SPIKES = "rln/spikes"
REWARD = "rln/reward"
ACTION = "rln/action"
WEIGHTS = "rln/weights"
# Every topic of the graph and its type, in causal order within a tick.
TOPIC_TYPES = {
    CLOCK: "rosgraph_msgs/msg/Clock",
    TRIAL_EVENT: "clnn_ros_msgs/msg/TrialEvent",
    STATE: "clnn_ros_msgs/msg/CartPoleState",
    MARKERS: "visualization_msgs/msg/MarkerArray",
    SPIKES: "clnn_ros_msgs/msg/SpikeVector",
    REWARD: "clnn_ros_msgs/msg/Reward",
    ACTION: "clnn_ros_msgs/msg/Action",
    WEIGHTS: "clnn_ros_msgs/msg/WeightSnapshot",
}
PER_TICK = (CLOCK, STATE, SPIKES, REWARD, ACTION)  # one message per tick
# Topics an environment of one's own may leave out (docs/ENV_CONTRACT.md): only viewers read them.
OPTIONAL = (MARKERS,)

# Plumbing (hidden): readiness announcements, the recorder's progress.
READY = "_graph/ready"
RECORDED = "_recorder/progress"
# The agent's service (private: /<namespace>/agent/save_checkpoint), std_srvs/Trigger.
SAVE_CHECKPOINT = "~/save_checkpoint"

# The nodes the trial manager waits for before the first tick, and the recorder's name.
GRAPH_NODES = ("environment", "encoder", "reward", "agent")
TRIAL_MANAGER = "trial_manager"
RECORDER = "recorder"
# Settings of a run that are not model parameters (every node takes them), with their defaults
# (clnn_ros.nodes.parameters describes them).
RUN_SETTINGS = {"seed": 0, "stall_timeout_s": 5.0, "out_dir": "", "progress": True,
                "extra_nodes": "", "external_nodes": "", "init_weights": "",
                "marker_period_ticks": 5}
# The trial manager's exit status when the graph never started: another graph of the same names
# runs in the namespace (0 done, 1 failed, 2 bad input, 128 + N signal N).
NOT_STARTED = 3
# Who publishes what within a tick, in causal order.
PUBLISHED_BY = {CLOCK: TRIAL_MANAGER, TRIAL_EVENT: TRIAL_MANAGER, STATE: "environment",
                SPIKES: "encoder", REWARD: "reward", ACTION: "agent", WEIGHTS: "agent"}


def absolute(topic: str, namespace: str = "/") -> str:
    """A relative name resolved in `namespace` ("/", "/robot1"): "/robot1/cartpole/state"."""
    return namespace.rstrip("/") + "/" + topic


def graph_topic(resolved: str) -> str:
    """The graph's relative name of a resolved topic name in any namespace ("/robot1/clock" ->
    "clock"); another topic's name unchanged."""
    return next((name for name in TOPIC_TYPES if resolved.endswith("/" + name)), resolved)
