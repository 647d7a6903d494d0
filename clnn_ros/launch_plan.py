"""What `ros2 launch clnn_ros graph.launch.py` starts: the processes of `python -m clnn_ros.run_all`
(one per node, the recorder first), each with run_all's parameters file, namespace, sim-clock
remapping and log level. The launch arguments are run_all's options, which run_all itself checks
and turns into parameters. No launch import: the tests check the plan where launch is not
installed; the launch file only turns it into launch_ros Node actions.

Unlike run_all, the launched graph writes results only with out:=DIR (run_all without --out
writes them into a temporary folder that it removes) and nothing supervises it: each node ends
by itself after the episode, as under run_all.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from . import run_all
from .names import GRAPH_NODES, RECORDER, TRIAL_MANAGER

# launch argument: (run_all option, description); an empty value leaves the option out
ARGUMENTS = {
    "seed": ("--seed", f"the episode's seed (run_all's default {run_all.DEMO['seed']})"),
    "trials": ("--trials", f"trials of the episode (default {run_all.DEMO['trials']})"),
    "nsv": ("--nsv", f"1: angle; 2: angle + cart velocity (default {run_all.DEMO['nsv']})"),
    "state_vars": ("--state-vars", "the encoded state variables instead, in input order, e.g. "
                                   "pole_angle,cart_position"),
    "params_file": ("--params-file", "a ROS 2 parameters YAML (/**: ros__parameters: ...)"),
    "namespace": ("--namespace", "put every node and topic under /NAME/"),
    "env": ("--env", f"environment node: {', '.join(run_all.ENVIRONMENTS)} (default cartpole)"),
    "out": ("--out", "write trials.csv, final_weights.npy, summary.json and the bag here"),
    "bag": ("--bag", "the bag directory of the recording (default <out>/bag with out, else "
                     "bags/run_<UTC time>)"),
}
RECORD = "record"  # launch argument: true (default) or false, as run_all's --no-record


@dataclass(frozen=True)
class NodeLaunch:
    executable: str  # lib/clnn_ros/<executable>, the console script of clnn_ros.nodes.<module>
    namespace: str  # "/" or "/NAME"
    params_file: Path
    remappings: tuple[tuple[str, str], ...]
    log_level: str = "warn"


def run_all_options(arguments: dict[str, str]) -> list[str]:
    """run_all's command line for these launch arguments."""
    options = []
    for name, (option, _) in ARGUMENTS.items():
        if arguments.get(name, ""):
            options += [option, arguments[name]]
    if arguments.get(RECORD, "true").lower() not in ("true", "1", "yes", "on"):
        options.append("--no-record")
    return options


def plan(arguments: dict[str, str], workdir: Path) -> list[NodeLaunch]:
    """The nodes to start, their parameters files written into workdir. Bad arguments: SystemExit
    with run_all's one error line; ParamError for bad parameters."""
    args = run_all.parse_args(run_all_options(arguments))
    values = run_all.build_parameters(args)
    values["out_dir"] = str(args.out.resolve()) if args.out else ""
    namespace = run_all.graph_namespace(args)
    remappings = tuple(run_all.clock_remappings(namespace))
    nodes = []
    if not args.no_record:
        bag_path = (args.bag or run_all.default_bag_path(args.out)).resolve()
        nodes.append(NodeLaunch(RECORDER, namespace, run_all.write_params(
            workdir / "recorder_params.yaml",
            {**values, "bag_path": str(bag_path), "environment": args.env}), remappings))
        values["extra_nodes"] = RECORDER
    environment = run_all.ENVIRONMENTS[args.env]
    if environment is None:
        values["external_nodes"] = "environment"
    params_file = run_all.write_params(workdir / "params.yaml", values)
    for name in (*GRAPH_NODES, TRIAL_MANAGER):
        if name == "environment":
            if environment is None:
                continue
            name = environment[0].rpartition(".")[2]
        nodes.append(NodeLaunch(name, namespace, params_file, remappings))
    return nodes
