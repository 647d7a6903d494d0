"""summary.md of an analysis (clnn_ros.analysis.analyze): what the bag holds and what the run did
(environment, physics, the task, encoding), the trials, and what each picture shows. A bag of
the cart-pole reads as it always did; another task's by its own names (env/task)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .data import OLDER_STATE_TYPE, UNFINISHED, gaps, input_labels
from .series import HISTORY_SEGMENTS
from ..core.params import CARTPOLE
from ..graph.fields import REACHED_MAX_STEPS
from ..graph.names import OLDER_STATE, OPTIONAL, PER_TICK, STATE, TASK, TOPIC_TYPES, absolute
from ..graph.ticks import RUN_END_NOTE, RUN_LAST_TICK_NOTE

# What each picture shows, for summary.md ({trial}: the chosen trial; trial_N.gif: ANIMATION).
PICTURES = {
    "learning_curve.png": "successful steps per trial, coloured by how each trial ended",
    "traces.png": "trial {trial} against the tick: cart position and velocity, pole angle and "
                  "angular velocity, action, reward and punishment, scaled to the motion",
    "raster.png": "trial {trial}'s spikes tick by tick (a long trial's first and last 200 "
                  "ticks, under an overview of the whole trial: the share of ticks each input "
                  "spiked), with the action, rewards and punishments",
    "weights.png": "the last weight snapshot, per neuron: segments (from 0) x the bag's input "
                   "intervals, on a colour scale from 0 to w_max; below, each weight's change "
                   "since the first snapshot",
    "weights_history.png": "every weight over the run, one panel per neuron and segment, one "
                           "line per input, a point per snapshot (trial end)",
}
ANIMATION = "trial {trial}'s cart and pole, with each tick's spikes and action beside them"
# ... of another task than the cart-pole ({variables}: its variables' names)
TASK_PICTURES = {
    "learning_curve.png": "successful steps per trial, coloured by how each trial ended; below, "
                          "each trial's return (the sum of its observations' rewards)",
    "traces.png": "trial {trial} against the tick: {variables}, the action, reward and "
                  "punishment, scaled to the motion",
}
# ... of a network of more than HISTORY_SEGMENTS segments
MANY_SEGMENTS = {"weights_history.png": "every input's weight over the run, its mean over the "
                                        "{segments} segments, one panel per neuron, a point per "
                                        "snapshot (trial end)"}
GYMNASIUM = "gymnasium:"  # run_all --env gymnasium:ID: the environment node runs Gymnasium's ID
# The recorder's `environment` (run_all's --env, or its --env-node command): what ran, and
# whose physics. Bags recorded before it was kept have none.
ENVIRONMENTS = {
    "cartpole": ("the built-in cart-pole node (`python -m clnn_ros.nodes.environment`)",
                 "`{physics}` equations, `{integrator}` integration (the built-in node's)"),
    "gymnasium": ("gymnasium's CartPole-v1 node (`python -m clnn_ros.nodes.environment`, "
                  "simulator gymnasium)",
                  "gymnasium's CartPole-v1 (the run's physics parameter does not apply)"),
    "mujoco": ("the MuJoCo cart-pole node (`python -m clnn_ros.nodes.environment`, simulator "
               "mujoco)",
               "MuJoCo's, with gymnasium CartPole-v1's constants (the run's physics parameter "
               "does not apply)"),
    "external": ("an external node (`run_all --env external`: started outside run_all)",
                 "the external node's own (the graph's parameter physics={physics}, which it "
                 "may ignore)"),
}
OWN_ENVIRONMENT = ("your own node: `{command}` (`run_all --env-node`)",
                   "the node's own (the graph's parameter physics={physics}, which it may "
                   "ignore)")
UNRECORDED_ENVIRONMENT = ("not recorded in this bag (a recorder that run_all did not start, or "
                          "an older recording)",
                          "parameter physics={physics}, integrator={integrator} (which node "
                          "computed it is not recorded)")


def environment_lines(data: dict, labels: list[str]) -> list[str]:
    """Markdown list items: the environment node, its physics, the encoding, the velocity edge
    (the cart-pole's; another task's edges per variable)."""
    params = data["params"]
    name = data["record"].get("environment", "")
    node, physics = ENVIRONMENTS.get(name) or (OWN_ENVIRONMENT if name else
                                               UNRECORDED_ENVIRONMENT)
    if name.startswith(GYMNASIUM):
        task = name[len(GYMNASIUM):]
        node = (f"Gymnasium's {task} (`run_all --env {name}`: the project's node, `python -m "
                f"clnn_ros.nodes.environment`, runs it)")
        physics = f"Gymnasium's {task} itself (the run's physics parameter does not apply)"
    described = data.get("task")
    if described is not None and described.task.name != CARTPOLE:
        edges = "; ".join(f"{v}: {', '.join(f'{e:g}' for e in cuts)}"
                          for v, cuts in params.variable_edges if v in params.state_vars)
        return [f"* environment: {node.format(command=name)}",
                "* physics: " + physics.format(physics=params.physics,
                                                integrator=params.integrator),
                f"* encoding: {', '.join(params.state_vars)} ({params.nsv} state variable"
                f"{'s' * (params.nsv > 1)}), {len(labels)} inputs: "
                + ", ".join(f"`{label}`" for label in labels) + f" (edges {edges})"]
    variables = "pole angle" if params.nsv == 1 else "pole angle and cart velocity"
    edges = ", ".join(f"{e:g}" for e in params.angle_edges_deg)
    velocity = (f"{params.velocity_edge:g} m/s (cart velocity intervals: below -e, [-e, e), e "
                f"and above)" if params.nsv == 2 else
                f"not used: 1 state variable encodes the pole angle only (parameter "
                f"{params.velocity_edge:g} m/s)")
    return [f"* environment: {node.format(command=name)}",
            f"* physics: " + physics.format(physics=params.physics,
                                            integrator=params.integrator),
            f"* encoding: {variables} ({params.nsv} state variable{'s' * (params.nsv > 1)}), "
            f"{len(labels)} inputs: "
            + ", ".join(f"`{label}`" for label in labels) + f" (angle edges {edges} deg)",
            f"* velocity edge: {velocity}"]


def task_line(data: dict) -> list[str]:
    """A markdown list item: the task as the bag's env/task describes it (none in a bag of
    before contract version 4, whose task is the paper's cart-pole)."""
    if TASK not in data.get("types", {}):
        return []
    task = data["task"].task

    def variable(v) -> str:
        unit = f" {v.unit}" if v.unit else ""
        bounds = f" [{v.low:g}, {v.high:g}]" if math.isfinite(v.low) or math.isfinite(v.high) \
            else ""
        return f"`{v.name}`{unit}{bounds}"

    reasons = data["task"].termination_reasons
    return [f"* task: `{task.name}` (the environment's env/task): {len(task.variables)} "
            f"variables {', '.join(map(variable, task.variables))}; {len(task.actions)} actions "
            + ", ".join(f"`{label}`" for label in task.action_labels)
            + (f"; truncated after {task.max_steps:,} steps" if task.max_steps else "")
            + f"; a terminated trial is a {task.ends_in}"
            + (f" ({', '.join(reasons)})" if reasons else "")
            + (f"; solved at a mean return of {task.reward_threshold:g}"
               if task.reward_threshold is not None else "")]


def topic_rows(data: dict) -> list[tuple[str, str]]:
    """(topic, type) of the messages table: the graph's topics, as the bag's version had them
    (a bag of before contract version 4: cartpole/state's CartPoleState, no env/task), but
    another task's optional ones (the cart-pole's markers) where the bag has none."""
    older = data["state_type"] == OLDER_STATE_TYPE
    left_out = (TASK,) if older else () if data["task"].task.name == CARTPOLE else OPTIONAL
    return [(topic, data["types"].get(topic, type_name)) for topic, type_name in
            TOPIC_TYPES.items() if topic in data["types"] or topic not in left_out]


def shown(data: dict, topic: str) -> str:
    """A topic's relative name as the bag has it (an older bag's state: cartpole/state)."""
    return OLDER_STATE if topic == STATE and data["state_type"] == OLDER_STATE_TYPE else topic


def run_end(end, notes: dict) -> tuple[str, int | None, str]:
    """How the run ended, its last tick (None: unknown) and where that is from: run_all's note in
    metadata.yaml (exact, and there even when the recorder missed the episode's end), else the
    EPISODE_END in the bag (the last trial's last tick, or the tick an early end waited for)."""
    try:
        last = int(notes[RUN_LAST_TICK_NOTE])
        return notes[RUN_END_NOTE], last, "run_all's note in metadata.yaml"
    except (KeyError, ValueError):
        pass
    if end is not None:
        return end.end_reason, end.tick - 1, "the bag's EPISODE_END"
    return "", None, ""


def bag_shortfall(data: dict, notes: dict, end) -> str:
    """Where a per-tick topic's last tick in the bag comes before the run's last tick, what the
    bag lacks, in one phrase ('' if nothing): in summary.md and on analyze's own output."""
    _, run_last, source = run_end(end, notes)
    ticks = data["ticks"]
    last = {topic: max(ticks[topic], default=-1) for topic in PER_TICK if topic in ticks}
    if run_last is None or not last or min(last.values()) >= run_last:
        return ""
    topic = min(last, key=last.get)
    return f"`{shown(data, topic)}` up to tick {last[topic]}, the run to tick {run_last} " \
           f"({source}; the recorder fell behind or stopped: the bag lacks ticks " \
           f"{last[topic] + 1}-{run_last})"


def mean_return(rows, returns: dict) -> str:
    """'; mean return R' of the completed trials, where the bag has their returns."""
    values = [returns[r[1]] for r in rows if r[1] in returns]
    return f"; mean return {np.mean(values):g}" if values else ""


def how_it_ended(end, reason: str, run_last: int | None) -> str:
    if end is not None:
        return f"EPISODE_END, `{end.end_reason}` at tick {end.tick}"
    if run_last is not None:
        return (f"`{reason}` after tick {run_last}, as run_all noted in metadata.yaml; the bag "
                f"holds no EPISODE_END (the recorder missed the episode's end)")
    return ("no EPISODE_END in the bag (interrupted, or the recorder stopped before the run did): "
            "how far the run went is not in the bag; its trials.csv says")


def summary_markdown(bag_path: Path, result: dict, salvage: bool) -> str:
    """summary.md's text, from what analyze() found and wrote (`result`)."""
    data, rows, chosen = result["data"], result["rows"], result["chosen"]
    returns = result.get("returns", {})
    steps = [r[3] for r in rows]
    params = data["params"]
    cap = params.max_steps
    end = result["episode_end"]
    reason, run_last, _ = run_end(end, data["notes"])
    inputs = result["final"].shape[2] if result["final"] is not None else params.n_inputs
    lines = [f"# Analysis of `{bag_path.name}`", "",
             "Rebuilt from the bag alone by `python -m clnn_ros.analysis`"
             + (" (salvaged: the file was not finished, only its complete chunks)" if salvage
                else "") + ".", "",
             "## Run", "",
             f"* seed {result['seed']}, step cap {cap:,}",
             *task_line(data),
             *environment_lines(data, input_labels(data, inputs)),
             "* how it ended: " + how_it_ended(end, reason, run_last),
             *([f"* **the bag ends before the run**: {short}"]
               if (short := bag_shortfall(data, data["notes"], end)) else []),
             f"* trials completed: {len(rows)}" + (
                 f"; mean successful steps {np.mean(steps):.1f}, best {max(steps):,}, last "
                 f"{steps[-1]:,}" if rows else "") + mean_return(rows, returns),
             ]
    first_cap = next((r[1] for r in rows if r[3] >= cap), None)
    goal = data["task"].task.ends_in == "success"
    if rows and goal:
        first_goal = next((r[1] for r in rows if r[4] != REACHED_MAX_STEPS), None)
        lines.append("* first trial to reach the goal (terminated): "
                     + (f"trial {first_goal}" if first_goal is not None else "none"))
    elif rows:
        lines.append("* first trial to reach the step cap: "
                     + (f"trial {first_cap}" if first_cap is not None else "none"))
        ends = {}
        for r in rows:
            ends[r[4]] = ends.get(r[4], 0) + 1
        lines.append("* trial ends: " + ", ".join(f"{k} {v}" for k, v in sorted(ends.items())))
    variables = ", ".join(data["task"].task.names)
    own = {} if data["task"].task.name == CARTPOLE else dict(TASK_PICTURES)
    segments = result["final"].shape[1] if result["final"] is not None else 0
    if segments > HISTORY_SEGMENTS:
        own.update(MANY_SEGMENTS)
    pictures = {name: own.get(name, what).format(trial=chosen and chosen["trial"],
                                                 variables=variables, segments=segments)
                for name, what in PICTURES.items()}
    if result["animated"] is not None:
        pictures[f"trial_{result['animated']}.gif"] = ANIMATION.format(trial=result["animated"])
    lines += ["", "## Pictures", ""]
    lines += [f"* `{name}`: {what}" for name, what in pictures.items()
              if name in result["produced"]]
    lines += ["", "## Messages", "", "| topic | type | messages | ticks | missing ticks |",
              "|---|---|---:|---|---:|"]
    for topic, type_name in topic_rows(data):
        if topic in data["ticks"]:
            first, last, missing = gaps(data["ticks"][topic])
            span = f"{first}-{last}" if first >= 0 else "-"
        else:
            span, missing = "-", "-"
        name = data["recorded_as"].get(topic, absolute(topic))
        lines.append(f"| `{name}` | `{type_name}` | {data['counts'].get(topic, 0):,} | {span} "
                     f"| {missing} |")
    if rows and data["task"].task.name == CARTPOLE:
        lines += ["", "## Trials", "", "| trial | initial angle (deg) | steps | end |",
                  "|---:|---:|---:|---|"]
        lines += [f"| {r[1]} | {r[2]:g} | {r[3]:,} | {r[4]} |" for r in rows]
    elif rows:  # another task: no initial angle; the return
        lines += ["", "## Trials", "", "| trial | steps | end | return |", "|---:|---:|---|---:|"]
        lines += [f"| {r[1]} | {r[3]:,} | {r[4]} | "
                  f"{f'{returns[r[1]]:g}' if r[1] in returns else '-'} |" for r in rows]
    if chosen:
        ended = "not ended in the bag" if chosen["end_reason"] == UNFINISHED else \
            f"ended by {chosen['end_reason']}"
        lines += ["", f"## Trial {chosen['trial']}", "",
                  f"Ticks {chosen['start']}-{chosen['end']} ({chosen['ticks']} states in the "
                  f"bag), {chosen['steps']:,} successful steps, {ended}.",
                  "", "![traces](traces.png)"]
        if "raster.png" in result["produced"]:
            lines += ["", "![raster](raster.png)"]
    if result["final"] is not None:
        w = result["final"]
        lines += ["", "## Weights", "",
                  f"{w.shape[0]} neurons x {w.shape[1]} segments x {w.shape[2]} inputs, "
                  f"published by the agent after trial {data['weights'][-1].trial} "
                  f"(`weights.csv` has all {len(data['weights'])} snapshots).", "",
                  "![weights](weights.png)", "", "![weights over the run](weights_history.png)"]
    if rows:
        lines += ["", "## Learning curve", "", "![learning curve](learning_curve.png)"]
    return "\n".join(lines) + "\n"
