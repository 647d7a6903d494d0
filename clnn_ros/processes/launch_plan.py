"""What `ros2 launch clnn_ros graph.launch.py` starts: the graph that `python -m clnn_ros.run_all`
starts, one process per node (the recorder first), each with the run's description (one params
file), namespace, sim-clock remapping and log level, as run_all gives them. The launch arguments
become the run's values through graph.run, as run_all's flags do. No launch import: the tests
check the plan where launch is not installed; the launch file only turns it into launch_ros Node
actions.

Unlike run_all, the launched graph writes results only with out:=DIR (run_all without --out
writes them into a temporary folder that it removes).

`Supervision` is what the launch does when a node's process exits (launch's OnProcessExit), as
run_all's supervise does: a node that fails ends the launch at once with one line naming it
(and a non-zero exit), so that neither a crash nor a node lost before the first tick leaves the
launch waiting on a stall or forever.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..core.params import ParamError
from ..files import cannot_create
from ..graph.names import (GRAPH_NODES, NOT_STARTED, RECORDER, TRIAL_MANAGER, clock_remappings,
                          namespace_problem)
from ..graph.run import DEMO, ENVIRONMENTS, RUN_SETTINGS, default_bag_path, run_values, write_params
from ..tasks import gymnasium_task
from ..tasks.gymnasium_task import PREFIX
from .supervise import RECORDER_GRACE_S, SHUTDOWN_GRACE_S, exit_description, unfinished_bag

# launch argument: description; an empty value leaves it out. RUN_VALUES are run values.
ARGUMENTS = {
    "seed": f"the episode's seed (default {DEMO['seed']})",
    "trials": f"trials of the episode (default {DEMO['trials']})",
    "nsv": f"1: angle; 2: angle + cart velocity (default {DEMO['nsv']})",
    "state_vars": "the encoded state variables instead, in input order, e.g. "
                  "pole_angle,cart_position",
    "max_steps": "successful steps that end a trial (default: the protocol's, 10000 for the "
                 "paper's; 500 for gymnasium)",
    "stall_timeout": "seconds without a tick before the trial manager ends the run (default "
                     f"{RUN_SETTINGS['stall_timeout_s']:g}; also how long env:=external's node is "
                     "waited for)",
    "rate": "at most this many ticks per second of wall time (50: real time; default 0: as "
            "fast as the graph goes)",
    "protocol": "paper (default: its 32 start angles) or gymnasium (CartPole-v1's random "
                "starts, truncated at 500 steps)",
    "params_file": "a ROS 2 parameters YAML (/**: ros__parameters: ...)",
    "namespace": "put every node and topic under /NAME/",
    "env": f"environment node: {', '.join(ENVIRONMENTS)} (default cartpole), or any Gymnasium "
           f"task, {PREFIX}ID (e.g. {PREFIX}Acrobot-v1)",
    "actions": f"env:={PREFIX}ID with a Box action space: the values the agent may apply, "
               f"e.g. -1,1",
    "out": "write trials.csv, final_weights.npy, summary.json and the bag here",
    "bag": "the bag directory of the recording (default <out>/bag with out, else "
           "bags/run_<UTC time>)",
}
RUN_VALUES = {"seed": "seed", "trials": "trials", "nsv": "nsv", "state_vars": "state_vars",
              "max_steps": "max_steps", "stall_timeout": "stall_timeout_s", "rate": "rate_hz",
              "protocol": "protocol"}  # launch argument: run value
RECORD = "record"  # launch argument: true (default) or false, as run_all's --no-record
# launch configurations that ros2 launch sets itself (its --launch-prefix, --launch-prefix-filter)
LAUNCH_OWN = ("launch-prefix", "launch-prefix-filter")


@dataclass(frozen=True)
class NodeLaunch:
    executable: str  # lib/clnn_ros/<executable>, the console script of clnn_ros.nodes.<module>
    namespace: str  # "/" or "/NAME"
    params_file: Path
    remappings: tuple[tuple[str, str], ...]
    log_level: str = "warn"
    bag_path: Path | None = None  # the recorder's


def plan(arguments: dict[str, str], workdir: Path) -> list[NodeLaunch]:
    """The nodes to start, the run's params files written into workdir. A bad argument, or one
    the launch file does not declare (launch itself takes any `name:=value`), is a ParamError
    with one line."""
    if unknown := sorted(set(arguments) - {*ARGUMENTS, RECORD}):
        raise ParamError(f"unknown launch argument {unknown[0]}:={arguments[unknown[0]]}; the "
                         f"arguments: {', '.join((*ARGUMENTS, RECORD))} (ros2 launch clnn_ros "
                         f"graph.launch.py --show-args)")
    given = {name: value for name, value in arguments.items() if value != ""}
    env = given.get("env", "cartpole")
    if env not in ENVIRONMENTS and not env.startswith(PREFIX):
        raise ParamError(f"env must be one of {', '.join(ENVIRONMENTS)} or {PREFIX}ID, "
                         f"got {env!r}")
    defaults = gymnasium_task.graph_defaults(env, DEMO, given.get("actions"))
    namespace = "/" + given["namespace"].strip("/") if "namespace" in given else "/"
    if "namespace" in given and (problem := namespace_problem(given["namespace"])):
        raise ParamError(f"namespace {given['namespace']!r}: {problem}")
    out = Path(given["out"]).resolve() if "out" in given else None
    if out is not None and (problem := cannot_create(out)):
        raise ParamError(f"out {out}: {problem}")
    flags = {value: given[name] for name, value in RUN_VALUES.items() if name in given}
    if env in ENVIRONMENTS and env != "external":
        flags["simulator"] = env
    values, _ = run_values(defaults, None, Path(given["params_file"]) if "params_file" in given
                           else None, flags=flags)
    values["out_dir"] = str(out) if out else ""
    remappings = tuple(clock_remappings(namespace))
    nodes = []
    if given.get(RECORD, "true").lower() in ("true", "1", "yes", "on"):
        bag_path = (Path(given["bag"]) if "bag" in given else default_bag_path(out)).resolve()
        nodes.append(NodeLaunch(RECORDER, namespace, write_params(
            workdir / "recorder_params.yaml",
            {**values, "bag_path": str(bag_path), "environment": env}), remappings,
            bag_path=bag_path))
        values["extra_nodes"] = RECORDER
    if env == "external":
        values["external_nodes"] = "environment"
    params_file = write_params(workdir / "params.yaml", values)
    return nodes + [NodeLaunch(name, namespace, params_file, remappings)
                    for name in (*GRAPH_NODES, TRIAL_MANAGER)
                    if name != "environment" or env != "external"]


@dataclass(frozen=True)
class Step:
    """What the launch does after an exit or when its timer fires: `fail`: end now with this
    line and a non-zero exit; `stop`: end now, normally (exit 0), saying this line; `timer`:
    None leaves the timer as it is, 0 cancels it, else it is started anew for that many
    seconds (then `Supervision.timed_out`)."""
    fail: str | None = None
    stop: str | None = None
    timer: float | None = None


class Supervision:
    """The launched graph's processes, watched as run_all watches them
    (clnn_ros.processes.supervise).
    `exited` is told each exit that happens while the launch is not shutting down (on the
    launch's own shutdown, Ctrl-C or a failure, every node is asked to stop: its exit is
    expected, whatever its status).

    * The trial manager exits 0: the episode is over; the others end by themselves on its
      EPISODE_END, within SHUTDOWN_GRACE_S (the recorder RECORDER_GRACE_S more); then the
      launch ends (exit 0), ending those still running.
    * A node exits with an error or a signal: the launch ends at once, failed. The trial manager
      with an error (a stall, another graph, a foreign publisher, a full disk) has told the
      others the episode ended: they get the grace to end (the recorder finishes the bag).
    * Another node exits 0 before the trial manager: after EPISODE_END, the trial manager
      itself ends within SHUTDOWN_GRACE_S; otherwise the node was stopped by someone else (the
      trial manager would wait for it with no end before the first tick, or stall): failed."""

    def __init__(self, names: list[str], bag_path: Path | None = None):
        self.running, self.bag_path = set(names), bag_path  # the recorder's bag, if any
        self.episode_over = False
        self.failure: str | None = None  # the line, once the launch is to fail
        self.quitter: str | None = None  # the first node that exited 0 before the episode end

    def end_grace_s(self) -> float:
        return SHUTDOWN_GRACE_S + (RECORDER_GRACE_S if RECORDER in self.running else 0.0)

    def exited(self, name: str, returncode: int) -> Step:
        self.running.discard(name)
        if returncode != 0:
            self.failure = self.failure or self.quit_early() or \
                exit_description(name, returncode) + unfinished_bag(name, self.bag_path)
            if name == TRIAL_MANAGER and 0 < returncode != NOT_STARTED and self.running:
                return Step(timer=self.end_grace_s())  # it sent EPISODE_END (giving way: not)
            return Step(fail=self.failure)
        if name == TRIAL_MANAGER:
            self.episode_over = True
            return Step(timer=self.end_grace_s() if self.running else 0.0)
        if self.episode_over or self.failure:
            if self.running:
                return Step()
            return Step(fail=self.failure) if self.failure else Step(timer=0.0)
        if self.quitter is None:
            self.quitter = name
            return Step(timer=SHUTDOWN_GRACE_S)
        return Step()

    def timed_out(self) -> Step:
        if self.episode_over and not self.failure:
            return Step(stop=f"{', '.join(sorted(self.running))} still running after the "
                             f"episode ended: stopped")
        return Step(fail=self.failure or self.quit_early())

    def quit_early(self) -> str | None:
        return exit_description(self.quitter, 0) if self.quitter else None
