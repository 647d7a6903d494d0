"""What `ros2 launch clnn_ros graph.launch.py` starts: the graph that `python -m clnn_ros.run_all`
starts, one process per node (the recorder first), each with the run's description (one params
file), namespace, sim-clock remapping and log level, as run_all gives them. The launch arguments
become the run's values through graph.run, as run_all's flags do. No launch import: the tests
check the plan where launch is not installed; the launch file only turns it into launch_ros Node
actions.

Unlike run_all, the launched graph writes results only with out:=DIR (run_all without --out
writes them into a temporary folder that it removes).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .core.params import ParamError
from .files import cannot_create
from .graph.names import GRAPH_NODES, RECORDER, TRIAL_MANAGER, clock_remappings, namespace_problem
from .graph.run import DEMO, ENVIRONMENTS, default_bag_path, run_values, write_params

# launch argument: description; an empty value leaves it out. The first five are run values.
ARGUMENTS = {
    "seed": f"the episode's seed (default {DEMO['seed']})",
    "trials": f"trials of the episode (default {DEMO['trials']})",
    "nsv": f"1: angle; 2: angle + cart velocity (default {DEMO['nsv']})",
    "state_vars": "the encoded state variables instead, in input order, e.g. "
                  "pole_angle,cart_position",
    "params_file": "a ROS 2 parameters YAML (/**: ros__parameters: ...)",
    "namespace": "put every node and topic under /NAME/",
    "env": f"environment node: {', '.join(ENVIRONMENTS)} (default cartpole)",
    "out": "write trials.csv, final_weights.npy, summary.json and the bag here",
    "bag": "the bag directory of the recording (default <out>/bag with out, else "
           "bags/run_<UTC time>)",
}
RUN_VALUES = ("seed", "trials", "nsv", "state_vars")
RECORD = "record"  # launch argument: true (default) or false, as run_all's --no-record


@dataclass(frozen=True)
class NodeLaunch:
    executable: str  # lib/clnn_ros/<executable>, the console script of clnn_ros.nodes.<module>
    namespace: str  # "/" or "/NAME"
    params_file: Path
    remappings: tuple[tuple[str, str], ...]
    log_level: str = "warn"


def plan(arguments: dict[str, str], workdir: Path) -> list[NodeLaunch]:
    """The nodes to start, the run's params files written into workdir. A bad argument is a
    ParamError with one line."""
    given = {name: value for name, value in arguments.items() if value != ""}
    env = given.get("env", "cartpole")
    if env not in ENVIRONMENTS:
        raise ParamError(f"env must be one of {', '.join(ENVIRONMENTS)}, got {env!r}")
    namespace = "/" + given["namespace"].strip("/") if "namespace" in given else "/"
    if "namespace" in given and (problem := namespace_problem(given["namespace"])):
        raise ParamError(f"namespace {given['namespace']!r}: {problem}")
    out = Path(given["out"]).resolve() if "out" in given else None
    if out is not None and (problem := cannot_create(out)):
        raise ParamError(f"out {out}: {problem}")
    flags = {name: given[name] for name in RUN_VALUES if name in given}
    if env != "external":
        flags["simulator"] = env
    values, _ = run_values(DEMO, None, Path(given["params_file"]) if "params_file" in given
                           else None, flags=flags)
    values["out_dir"] = str(out) if out else ""
    remappings = tuple(clock_remappings(namespace))
    nodes = []
    if given.get(RECORD, "true").lower() in ("true", "1", "yes", "on"):
        bag_path = (Path(given["bag"]) if "bag" in given else default_bag_path(out)).resolve()
        nodes.append(NodeLaunch(RECORDER, namespace, write_params(
            workdir / "recorder_params.yaml",
            {**values, "bag_path": str(bag_path), "environment": env}), remappings))
        values["extra_nodes"] = RECORDER
    if env == "external":
        values["external_nodes"] = "environment"
    params_file = write_params(workdir / "params.yaml", values)
    return nodes + [NodeLaunch(name, namespace, params_file, remappings)
                    for name in (*GRAPH_NODES, TRIAL_MANAGER)
                    if name != "environment" or env != "external"]
