"""The graph's parameters as ROS parameters: each declared with a ParameterDescriptor (a
description, its range or choices, read-only: every one is read once at start), so that
`ros2 param describe` shows the constraints and `ros2 param set` is refused with a reason.

Every node of the graph takes every parameter (one params file for the whole graph): the model's
(core Params) and the run settings (RUN_SETTINGS). A name that is neither is an error."""

from __future__ import annotations

import sys
from pathlib import Path

import yaml
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node

from ..names import RUN_SETTINGS
from ..core.params import (DECAY_COUNTERS, E_FLAGS, FIRST_ACTION, INFERENCE, INTEGRATORS,
                           MAX_SEGMENTS, PHYSICS, PUNISH_TIMING, STATE_NAMES, SUCCESS_COUNTER,
                           TAGGING, TIE_BREAKS, ParamError, Params, params_from_strings)

# Parameters rclpy itself declares.
ROS_BUILTIN_PARAMETERS = {"use_sim_time", "start_type_description_service"}

COUNT = (1, 2**31 - 1)  # counts travel in the messages' uint32 fields
POSITIVE = (0.0, sys.float_info.max)  # > 0 (Params refuses 0)
NON_NEGATIVE = (0.0, sys.float_info.max)
# name: (description, (lowest, highest) or choices)
DESCRIPTIONS = {
    "nsv": ("how many state variables are encoded: 1 = pole angle, 2 = angle and cart velocity, "
            "3 and 4 add cart position and pole angular velocity (or as state_vars says)", (1, 4)),
    "state_vars": ("the encoded state variables, in input order (any of: "
                   + ", ".join(STATE_NAMES) + ")", None),
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
    "physics": ("cart-pole equations: paper (its units slip), correct, or integration_slip (the "
                "slip in the pole's integration only)", PHYSICS),
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
}


def descriptor(name: str, description: str | None = None) -> ParameterDescriptor:
    """Read-only, with its description and constraints."""
    text, constraint = DESCRIPTIONS.get(name, (description or "", None))
    result = ParameterDescriptor(name=name, description=text, read_only=True)
    if constraint and isinstance(constraint[0], str):
        result.additional_constraints = "one of: " + ", ".join(constraint)
    elif constraint and isinstance(constraint[0], int):
        result.integer_range = [IntegerRange(from_value=constraint[0], to_value=constraint[1],
                                             step=1)]
    elif constraint:
        result.floating_point_range = [FloatingPointRange(from_value=constraint[0],
                                                          to_value=constraint[1])]
    return result


def declare_parameters(node: Node, own: dict[str, tuple] | None = None) -> tuple[Params, dict]:
    """Every parameter given to the node (command line, --params-file or in-process overrides),
    validated: model parameters become a core Params, the rest the run settings (and the node's
    `own`: {name: (default, description)}); an unknown name is a ParamError. Then all of them
    are declared with their descriptors and values, so all are listed."""
    given = {name: p.value for name, p in node.get_parameters_by_prefix("").items()
             if name not in ROS_BUILTIN_PARAMETERS}
    for name in given:  # declared from the overrides, without descriptors: declared again below
        node.undeclare_parameter(name)
    settings = dict(RUN_SETTINGS)
    for name in set(given) & set(settings):
        settings[name] = convert_setting(name, given.pop(name))
    for name, (default, _) in (own or {}).items():
        settings[name] = given.pop(name, default)
    params = params_from_strings(given)
    descriptions = {name: description for name, (_, description) in (own or {}).items()}
    # Params.segments None is the paper's count for nsv; a ROS parameter has no null value, so
    # the node shows the count its network has.
    declared = {**params.to_dict(), "segments": params.n_segments, **settings}
    for name, value in declared.items():
        value = list(value) if isinstance(value, tuple) else value
        node.declare_parameter(name, value, descriptor(name, descriptions.get(name)),
                               ignore_override=True)
    return params, settings


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
