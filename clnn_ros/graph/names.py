"""The graph's names: nodes, topics, who publishes what, and the namespace rule. Topic names are
relative: a node resolves them in its namespace, so `-r __ns:=/robot1` (or run_all --namespace
robot1) moves the whole graph to /robot1/... Names whose first token starts with `_` are
plumbing, hidden by ROS's convention (`ros2 topic list` shows them only with
--include-hidden-topics)."""


CLOCK = "clock"
TRIAL_EVENT = "trial/event"
# The environment's observation every tick, and its task, once, latched (contract version 4)
STATE = "env/observation"
TASK = "env/task"
# Where an environment node of contract versions 1 to 3 published its state (CartPoleState): the
# graph names such a node instead of waiting for its observations.
OLDER_STATE = "cartpole/state"
# The cart-pole drawn for a 3D view (the cart-pole's own, optional)
MARKERS = "cartpole/markers"
SPIKES = "rln/spikes"
REWARD = "rln/reward"
ACTION = "rln/action"
WEIGHTS = "rln/weights"
# What each encoder input means: once per run, latched (the spike vectors carry no text).
INPUT_LABELS = "rln/input_labels"
# Every topic of the graph and its type, in causal order within a tick.
TOPIC_TYPES = {
    CLOCK: "rosgraph_msgs/msg/Clock",
    TRIAL_EVENT: "clnn_ros_msgs/msg/TrialEvent",
    TASK: "clnn_ros_msgs/msg/TaskDescription",
    STATE: "clnn_ros_msgs/msg/Observation",
    MARKERS: "visualization_msgs/msg/MarkerArray",
    SPIKES: "clnn_ros_msgs/msg/SpikeVector",
    REWARD: "clnn_ros_msgs/msg/Reward",
    ACTION: "clnn_ros_msgs/msg/Action",
    WEIGHTS: "clnn_ros_msgs/msg/WeightSnapshot",
    INPUT_LABELS: "clnn_ros_msgs/msg/InputLabels",
}
PER_TICK = (CLOCK, STATE, SPIKES, REWARD, ACTION)  # one message per tick
LATCHED = (TASK, INPUT_LABELS)  # once per run, kept for a subscriber that joins later
# Topics an environment of one's own may leave out (docs/ENV_CONTRACT.md): only viewers read them.
OPTIONAL = (MARKERS,)

# Plumbing (hidden): readiness announcements, the trial managers' claims (graph.watch.graph_claim),
# the recorder's progress.
READY = "_graph/ready"
CLAIM = "_graph/claim"
RECORDED = "_recorder/progress"
# The agent's service (private: /<namespace>/agent/save_checkpoint), std_srvs/Trigger.
SAVE_CHECKPOINT = "~/save_checkpoint"

# The version of the environment-node contract (docs/ENV_CONTRACT.md, "Versions"): what an
# environment node written against it publishes and reads. The checker prints it.
ENV_CONTRACT_VERSION = 4
# The nodes the trial manager waits for before the first tick, and the recorder's name.
ENVIRONMENT = "environment"
GRAPH_NODES = (ENVIRONMENT, "encoder", "reward", "agent")
# The graph nodes that run on the graph's sim time (use_sim_time, whose TimeSource subscribes
# /clock): the environment, per its contract (docs/ENV_CONTRACT.md). The others read no ROS time.
SIM_TIME_NODES = ("environment",)
TRIAL_MANAGER = "trial_manager"
RECORDER = "recorder"
# The trial manager's exit status when the graph never started: another graph of the same names
# runs in the namespace (0 done, 1 failed, 2 bad input, 128 + N signal N).
NOT_STARTED = 3
# Who publishes what within a tick, in causal order.
PUBLISHED_BY = {CLOCK: TRIAL_MANAGER, TRIAL_EVENT: TRIAL_MANAGER, STATE: ENVIRONMENT,
                SPIKES: "encoder", REWARD: "reward", ACTION: "agent", WEIGHTS: "agent",
                INPUT_LABELS: "encoder", MARKERS: ENVIRONMENT, TASK: ENVIRONMENT}


def absolute(topic: str, namespace: str = "/") -> str:
    """A relative name resolved in `namespace` ("/", "/robot1"): "/robot1/env/observation"."""
    return namespace.rstrip("/") + "/" + topic


def graph_topic(resolved: str) -> str:
    """The graph's relative name of a resolved topic name in any namespace ("/robot1/clock" ->
    "clock"); another topic's name unchanged."""
    return next((name for name in TOPIC_TYPES if resolved.endswith("/" + name)), resolved)


def namespace_problem(name: str) -> str | None:
    """Why `name` is not a ROS namespace (tokens of letters, digits and _, not starting with a
    digit, separated by /), or None."""
    tokens = name.strip("/").split("/")
    if not name.strip("/") or not all(t and (t[0].isalpha() or t[0] == "_") and
                                      all(c.isalnum() or c == "_" for c in t) and t.isascii()
                                      for t in tokens):
        return "expected letters, digits and _ (not starting with a digit), '/' between levels"
    return None


def clock_remappings(namespace: str) -> list[tuple[str, str]]:
    """The sim clock moved into the namespace (use_sim_time subscribes to the absolute /clock)."""
    return [("/clock", f"{namespace}/clock")] if namespace != "/" else []
