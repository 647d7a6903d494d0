"""What a run is, without ROS: its settings, the model parameters (core Params), which node takes
which, and how the values of a run are put together from a preset, a params file, options and
flags. run_all, the launch file and a node started by hand all read the same description: one
ROS 2 parameters YAML (`/**: {ros__parameters: {...}}`) with every value of the run, from which
each node takes the parameters it uses (NODE_PARAMETERS) and declares only those."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import yaml

from ..core.physics import GYM_PHYSICS
from ..core.params import (DECAY_COUNTERS, E_FLAGS, FIRST_ACTION, INFERENCE, INTEGRATORS,
                           MAX_ACTIONS, MAX_SEGMENTS, PHYSICS, PROTOCOLS, PUNISH_TIMING,
                           REWARD_MAPPINGS, STATE_NAMES, SUCCESS_COUNTER, TAGGING, TIE_BREAKS,
                           ParamError, Params, params_from_strings, protocol_defaults,
                           variable_edges_text)
from ..core.presets import overlay_values, preset_values
from .names import RECORDER, TRIAL_MANAGER, clock_remappings

# Settings of a run that are not model parameters, with their defaults.
RUN_SETTINGS = {"seed": 0, "stall_timeout_s": 5.0, "out_dir": "", "progress": True,
                "extra_nodes": "", "external_nodes": "", "init_weights": "",
                "marker_period_ticks": 5, "simulator": "cartpole",
                "allow_foreign_publishers": False, "rate_hz": 0, "actions": ""}
# The simulators the project's environment node runs (its setting `simulator`), and external:
# none is started, one started by someone else is waited for (docs/ENV_CONTRACT.md).
SIMULATORS = ("cartpole", "gymnasium", "mujoco")
ENVIRONMENTS = (*SIMULATORS, "external")
# The environments whose simulator steps its own tau (gymnasium's CartPole-v1, and the MuJoCo
# plant built with its constants): one tick is one of their steps.
OWN_TAU = {"gymnasium": GYM_PHYSICS["tau"], "mujoco": GYM_PHYSICS["tau"]}
# The demonstration: seed 0 goes from 32 steps to the 10,000 cap by trial 11 (about 80k ticks).
DEMO = dict(seed=0, trials=20, nsv=1)
# Run settings that run_all and the launch file set themselves: a value given would be
# overwritten (out_dir) or make the graph wait for a participant that never comes (extra_nodes,
# the recorder's name).
SET_BY_THE_RUN = {"out_dir": "--out", "extra_nodes": "--bag / --no-record",
                  "external_nodes": "--env external"}

# Which node takes which parameter: those it reads, and those its topics' content rules read
# (graph.content). A node given a parameter of the run that it does not take ignores it.
ENCODING = ("task", "nsv", "state_vars", "variable_edges", "angle_edges_deg", "velocity_edge", "position_edges_m",
            "angular_velocity_edges_deg_per_s")
NETWORK = (*ENCODING, "segments", "n_actions")
STATE_RULE = ("max_steps", "angle_limit_deg", "track_limit_m")
LEARNING = ("reward_mapping", "sigma", "omega", "rho_plus", "rho_minus", "punish", "w_max", "w_base", "w_range",
            "tie_break", "tagging", "e_flag", "success_counter", "decay_counters",
            "punish_timing", "inference", "explore", "rerandomize_every",
            "rerandomize_fraction", "rerandomize_range")
PHYSICS_PARAMETERS = ("physics", "integrator", "cart_mass", "pole_mass", "pole_length",
                      "gravity", "force", "angle_limit_deg", "track_limit_m", "first_action")
# Every node stamps its messages with the tick's sim time (tau), and waits for extra_nodes.
COMMON = ("tau", "extra_nodes")
# A resumed episode (init_weights: a checkpoint) is checked against the node's own parameters.
RESUME = ("seed", "init_weights", "trials")
NODE_PARAMETERS = {
    # segments: an action's winner must exist in the network (graph.content.action_problem)
    "environment": (*COMMON, *PHYSICS_PARAMETERS, "max_steps", "marker_period_ticks",
                    "simulator", "segments", "protocol", "task", "n_actions", "actions"),
    "encoder": (*COMMON, *ENCODING, *STATE_RULE, "n_actions"),
    # task: what its rewards mean (a cart-pole's are refused by reward_mapping shaped)
    "reward": (*COMMON, *STATE_RULE, "task", "sigma", "omega", "success_counter",
               "reward_mapping", *RESUME),
    # every model parameter: its checkpoints hold the whole episode's (a resume runs under the
    # saving run's protocol, max_steps, physics, not under defaults)
    "agent": (*COMMON, *dict.fromkeys((*NETWORK, *LEARNING, *Params().to_dict())), *RESUME,
              "out_dir"),
    TRIAL_MANAGER: (*COMMON, *NETWORK, *STATE_RULE, *RESUME, "w_max", "n_angles",
                    "angle_span_deg", "protocol", "stall_timeout_s", "out_dir", "progress",
                    "external_nodes", "allow_foreign_publishers", "rate_hz"),
}
# What the run's params file always holds, at its effective value, for an environment node of
# someone else's: the parameters of docs/ENV_CONTRACT.md's table (tests/test_env_contract.py
# holds them equal). Not extra_nodes (the run sets it), nor simulator (the project's node's own
# setting: an --env-node command's -p simulator:=... must not be overridden).
ENVIRONMENT_GIVEN = ("tau", *PHYSICS_PARAMETERS, "max_steps", "marker_period_ticks",
                     "segments", "protocol", "task", "n_actions")
# The recorder keeps every value of the run in its bag.
NODE_PARAMETERS[RECORDER] = tuple(sorted({*Params().to_dict(), *RUN_SETTINGS}))

COUNT = (1, 2**31 - 1)  # counts travel in the messages' uint32 fields
POSITIVE = (0.0, sys.float_info.max)  # > 0 (Params refuses 0)
NON_NEGATIVE = (0.0, sys.float_info.max)
# name: (description, (lowest, highest) or choices)
DESCRIPTIONS = {
    "nsv": ("how many state variables are encoded: 1 = pole angle, 2 = angle and cart velocity, "
            "3 and 4 add cart position and pole angular velocity (or as state_vars says; "
            "another task's: as many as state_vars names)", (1, 2**16 - 1)),
    "state_vars": ("the encoded state variables, in input order (the cart-pole's: any of "
                   + ", ".join(STATE_NAMES) + "; another task's: names of variable_edges)",
                   None),
    "segments": ("dendritic segments per neuron; not given: half the input combinations, the "
                 "paper's 3 for 1 SV and 9 for 2 SV (declared with the count in use)",
                 (1, MAX_SEGMENTS)),
    "sigma": ("success window: a positive reward every sigma successful steps", COUNT),
    "omega": ("punishment window: length of the action path punished on a failure", COUNT),
    "rho_plus": ("maximum reward capture (synapses whose e flag is 1)", NON_NEGATIVE),
    "rho_minus": ("maximum reward backoff (synapses whose e flag is 0)", NON_NEGATIVE),
    "punish": ("pi: maximum punishment decrement", NON_NEGATIVE),
    "w_max": ("largest synaptic weight", POSITIVE),
    "w_base": ("initial weights: w_base + uniform [0, w_range)", NON_NEGATIVE),
    "w_range": ("initial weights: w_base + uniform [0, w_range)", NON_NEGATIVE),
    "trials": ("trials of the episode", COUNT),
    "max_steps": ("successful steps that end a trial", COUNT),
    "n_angles": ("initial angles, evenly spaced over +-angle_span_deg", COUNT),
    "angle_span_deg": ("initial angles span +-this, deg", NON_NEGATIVE),
    "angle_edges_deg": ("encoder: interior edges of the pole-angle intervals, deg (Table 1)",
                        None),
    "velocity_edge": ("encoder: |cart velocity| edge between its 3 intervals, m/s", POSITIVE),
    "position_edges_m": ("encoder: interior edges of the cart-position intervals, m", None),
    "angular_velocity_edges_deg_per_s": ("encoder: interior edges of the pole angular-velocity "
                                         "intervals, deg/s", None),
    "physics": ("cart-pole equations: paper (its units slip), correct, integration_slip (the "
                "slip in the pole's integration only), or gymnasium (CartPole-v1's step itself, "
                "in radians)", PHYSICS),
    "protocol": ("paper (its 32 start angles, the cart at rest) or gymnasium (CartPole-v1's "
                 "random starts, drawn by the environment from the START's seed; truncated at "
                 "500 steps)", PROTOCOLS),
    "integrator": ("physics integration", INTEGRATORS),
    "cart_mass": ("kg", POSITIVE), "pole_mass": ("kg", POSITIVE),
    "pole_length": ("half the pole's length, m", POSITIVE), "gravity": ("m/s^2", POSITIVE),
    "force": ("magnitude of the force on the cart, N", NON_NEGATIVE),
    "tau": ("one tick: the physics step, s of sim time", POSITIVE),
    "angle_limit_deg": ("a trial fails beyond this pole angle, deg (at most 12)", (0.0, 12.0)),
    "track_limit_m": ("a trial fails beyond this cart position, m", POSITIVE),
    "tie_break": ("winner-take-all ties", TIE_BREAKS),
    "tagging": ("which segments are tagged for learning", TAGGING),
    "e_flag": ("e flag latched at tagging or read at reward time", E_FLAGS),
    "success_counter": ("success counter reset each trial or carried", SUCCESS_COUNTER),
    "decay_counters": ("decay counters and e flags reset each trial or carried", DECAY_COUNTERS),
    "first_action": ("the network acts on the initial state, or the pole is released with F = 0 "
                     "for one step first", FIRST_ACTION),
    "punish_timing": ("the punished path's head gets omega (before the decay) or omega - 1",
                      PUNISH_TIMING),
    "inference": ("segment response: sum of ceil(w) or of w", INFERENCE),
    "explore": ("probability that the network WTA's winner is overruled and the other neuron "
                "acts (a way out of local optima; the paper: 0)", (0.0, 1.0)),
    "rerandomize_every": ("the paper's section 5 proposal: at the start of every this-many-th "
                          "trial some synapses are re-drawn; 0: never (the paper's model)",
                          (0, 2**31 - 1)),
    "rerandomize_fraction": ("re-randomization: the probability that a synapse is re-drawn",
                             (0.0, 1.0)),
    "rerandomize_range": ("re-randomization: a re-drawn weight is w_base + uniform "
                          "[0, rerandomize_range)", NON_NEGATIVE),
    "task": ("the task: cartpole (the paper's and its variants), or another task's name, e.g. "
             "gymnasium:Acrobot-v1; the environment node's env/task must name it", None),
    "actions": ("a Gymnasium task with a Box action space: the values the agent may apply, "
                "e.g. -1,1 ('': a Discrete space's every action, or a known task's own)", None),
    "n_actions": ("actions of the task, one RLN each (the cart-pole's 2: -F, +F)",
                  (2, MAX_ACTIONS)),
    "reward_mapping": ("failure: a reward every sigma successful steps, a punishment when the "
                       "episode terminates (the paper's); goal: a reward when it terminates (a "
                       "goal reached), a punishment every omega steps without it; shaped: the "
                       "sign of the task's rewards summed since the last signal, every sigma "
                       "steps and when the episode terminates", REWARD_MAPPINGS),
    "variable_edges": ("encoder: another task's variables and their interior edges, "
                       "name:e1,e2;name2:e1 ('' for the cart-pole)", None),
    "seed": ("the episode's seed: initial weights, initial angles", (0, 2**32 - 1)),
    "stall_timeout_s": ("seconds without progress before the graph is declared stalled",
                        POSITIVE),
    "out_dir": ("where trials.csv, summary.json, checkpoints go ('' none)", None),
    "progress": ("print a line per trial", None),
    "extra_nodes": ("comma-separated participants that subscribe to every topic and announce "
                    "readiness (the recorder): the graph waits for them", None),
    "external_nodes": ("comma-separated graph nodes started by someone else (an environment "
                       "on a robot): waited for at most stall_timeout_s once the rest is ready",
                       None),
    "init_weights": ("'' the seed's; fig7, fig12, a weights .npy, or a checkpoint .npz to "
                     "resume", None),
    "marker_period_ticks": ("the environment draws the cart-pole on cartpole/markers (a 3D "
                            "view) at every tick that is a multiple of this; 0: never",
                            (0, 2**32 - 1)),
    "allow_foreign_publishers": ("a publisher on a graph topic that is not the graph's node "
                                 "(forged messages) ends the run (false), or is named and the "
                                 "run goes on, its results reported as tainted (true)", None),
    "rate_hz": ("ticks per second of wall time at most, e.g. 50 (tau 0.02 s: real time), so "
                "that ros2 topic echo, rqt or Foxglove follow the run as a robot runs; 0: as "
                "fast as the graph goes", (0, 2**32 - 1)),
    "simulator": ("what the environment node simulates: cartpole (the core's physics, as the "
                  "model parameters say), gymnasium (CartPole-v1's own constants) or mujoco "
                  "(a MuJoCo plant with gymnasium's constants)", SIMULATORS),
}


def read_params_file(path) -> dict:
    """The parameters of a ROS 2 parameters YAML (`<node>: {ros__parameters: {...}}`, every
    node's section merged), or one ParamError line: rcl itself takes some bad files silently
    (a file without any `ros__parameters` section) and refuses others with a traceback. The
    graph's nodes share their parameters, so two sections must not give a name two values."""
    try:
        document = yaml.safe_load(Path(path).read_text())
    except (OSError, UnicodeDecodeError) as error:
        raise ParamError(f"cannot read params file {path}: {error}") from None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        raise ParamError(f"params file {path} is not valid YAML: "
                         f"{getattr(error, 'problem', None) or error}{where}") from None
    sections = {node: v.get("ros__parameters") for node, v in document.items()
                if isinstance(v, dict)} if isinstance(document, dict) else {}
    if not sections or not all(isinstance(s, dict) for s in sections.values()):
        raise ParamError(f"params file {path} must map node names to 'ros__parameters:' "
                         f"mappings, e.g. '/**: {{ros__parameters: {{sigma: 256}}}}'")
    merged, given_by = {}, {}
    for node, section in sections.items():
        for name, value in section.items():
            if name in merged and merged[name] != value:
                raise ParamError(f"params file {path} gives {name} two values ({merged[name]!r} "
                                 f"for {given_by[name]}, {value!r} for {node}); the graph's "
                                 f"nodes share their parameters")
            merged[name], given_by[name] = value, node
    return merged


def convert_setting(name: str, value):
    """A run setting (RUN_SETTINGS) from the command line, a ROS parameter or YAML, checked:
    its default's type (text of a number counts as the number), else one ParamError line."""
    default = RUN_SETTINGS[name]
    if isinstance(default, (bool, str)):
        if type(value) is not type(default):
            expected = "true or false" if isinstance(default, bool) else "text"
            raise ParamError(f"{name} must be {expected}, got {value!r}")
        choices = DESCRIPTIONS[name][1]
        if choices and value not in choices:
            raise ParamError(f"{name} must be one of {', '.join(choices)}, got {value!r}")
        return value
    if isinstance(value, str):
        try:
            value = int(value, 10) if isinstance(default, int) else float(value)
        except ValueError:
            pass  # refused below with the text itself
    if isinstance(default, int):  # the seed: TrialEvent.seed is a uint32
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**32:
            raise ParamError(f"{name} must be an integer from 0 to 2**32-1, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not 0 < value < float("inf"):
        raise ParamError(f"{name} must be a finite number > 0, got {value!r}")
    return float(value)


def names_list(setting: str) -> set[str]:
    """The names of a comma-separated setting (extra_nodes, external_nodes)."""
    return {name.strip() for name in setting.split(",") if name.strip()}


def node_parameters(run: dict, node: str, own: dict | None = None) -> tuple[Params, dict]:
    """What `node` takes of a run's values: a validated Params of the model parameters it uses
    (the others at their defaults) and its run settings (and its `own`: {name: default}). A
    name that is no parameter of the run is a ParamError; one that the node does not use is
    ignored (one params file serves every node)."""
    own = own or {}
    known = {*Params().to_dict(), *RUN_SETTINGS, *own}
    if unknown := sorted(set(run) - known):
        raise ParamError(f"unknown parameter {unknown[0]!r}; known: {', '.join(sorted(known))}")
    # Every value given is checked as run_all checks it, those the node leaves to others too:
    # a node started by hand with -p trials:=0 says so rather than run.
    params_from_strings({name: value for name, value in run.items()
                         if name not in RUN_SETTINGS and name not in own})
    for name in set(run) & set(RUN_SETTINGS):
        convert_setting(name, run[name])
    used = NODE_PARAMETERS[node]
    settings = {name: convert_setting(name, run.get(name, RUN_SETTINGS[name]))
                for name in used if name in RUN_SETTINGS}
    settings.update({name: run.get(name, default) for name, default in own.items()})
    params = params_from_strings({name: value for name, value in run.items()
                                  if name in used and name not in RUN_SETTINGS})
    return params, settings


def declared_values(params: Params, settings: dict, node: str) -> dict:
    """The values a node shows as its ROS parameters: those it uses, as it uses them (segments
    not given: the count its network has; a ROS parameter has no null value)."""
    model = {**params.to_dict(), "segments": params.n_segments,
             "variable_edges": variable_edges_text(params.variable_edges)}
    values = {name: model[name] for name in NODE_PARAMETERS[node] if name in model}
    return {**values, **settings}


def run_values(defaults: dict, preset: str | None = None, params_file: Path | None = None,
               options: dict | None = None, flags: dict | None = None) -> tuple[dict, Params]:
    """A run's values, each layer over the one before: `defaults` (the demonstration's or a
    resumed checkpoint's), the preset, the params file, the options, the flags; checked here,
    before any node starts. Returns the values every node is given and the run's Params."""
    values = dict(defaults)
    for layer in (preset_values(preset) if preset is not None else {},
                  read_params_file(params_file) if params_file is not None else {},
                  options or {}, flags or {}):
        values = overlay_values(values, layer)
    values = protocol_defaults(values)
    for name, option in SET_BY_THE_RUN.items():
        if name in values:
            raise ParamError(f"{name} is set by run_all ({option}), not as a parameter")
    model = {k: v for k, v in values.items() if k not in RUN_SETTINGS}
    params = params_from_strings(model)  # raises ParamError with one line
    # The nodes get the checked values: rcl refuses e.g. a list mixing ints and floats.
    values.update({k: list(v) if isinstance(v, tuple) else v
                   for k, v in params.to_dict().items() if k in model})
    if "variable_edges" in model:  # a ROS parameter is no nested list: its text
        values["variable_edges"] = variable_edges_text(params.variable_edges)
    values["nsv"] = params.nsv  # the count state_vars gives
    for key in set(values) & set(RUN_SETTINGS):
        values[key] = convert_setting(key, values[key])
    # An environment node of someone else's knows no defaults of ours: the physics as numbers.
    model = {**params.to_dict(), "segments": params.n_segments}  # the count in use, not None
    for name in ENVIRONMENT_GIVEN:
        if name not in values:
            value = model[name] if name in model else RUN_SETTINGS[name]
            values[name] = list(value) if isinstance(value, tuple) else value
    return values, params


def write_params(path: Path, values: dict) -> Path:
    """The run's description: a params file that gives every node the run's values (each takes
    those it uses)."""
    path.write_text(yaml.dump({"/**": {"ros__parameters": values}}, Dumper=QuotingDumper))
    return path


class QuotingDumper(yaml.SafeDumper):
    """Every string quoted: rcl's YAML reads a bare y, n, on, off as a bool (a variable named y,
    LunarLander's height, made state_vars a list mixing strings and a bool)."""


QuotingDumper.add_representer(
    str, lambda dumper, text: dumper.represent_scalar("tag:yaml.org,2002:str", text, style="'"))


def node_arguments(params_file: Path, namespace: str) -> list[str]:
    """The --ros-args of every node of a run: the run's description, and the namespace with the
    sim clock moved into it."""
    arguments = ["--ros-args", "--params-file", str(params_file), "--log-level", "warn"]
    if namespace != "/":
        arguments += ["-r", f"__ns:={namespace}"]
    for old, new in clock_remappings(namespace):
        arguments += ["-r", f"{old}:={new}"]
    return arguments


def default_bag_path(out_dir: Path | None) -> Path:
    """<out>/bag with an output folder, else bags/run_<UTC time> under the current directory."""
    if out_dir is not None:
        return Path(out_dir) / "bag"
    return Path("bags") / time.strftime("run_%Y%m%d_%H%M%S", time.gmtime())
