"""Parameters of the model: Table 2 of Smith (2024) plus every choice the paper leaves open.

Each open choice is a named option whose default is the convention that reproduces the paper's
numbers (see docs/REPRODUCTION.md for the evidence and the effect of switching each one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

PHYSICS = ("paper", "correct", "integration_slip", "gymnasium")
PROTOCOLS = ("paper", "gymnasium")
# What the rule's reward and punishment mean for a task (core.rln.task_outcome): "failure", the
# paper's, for a task whose episode terminates in failure (a reward every sigma successful
# steps, a punishment when it terminates); "goal", for one whose episode terminates in success
# (reaching a goal: a reward when it terminates, a punishment every omega steps without it);
# "shaped", for one whose every step's reward says how well it goes (LunarLander-v3): every
# sigma steps, and when a step terminates the episode, the sign of the rewards' sum since.
REWARD_MAPPINGS = ("failure", "goal", "shaped")
CARTPOLE = "cartpole"  # Params.task of the paper's cart-pole and its variants
MAX_ACTIONS = 255  # Action.action is a uint8 (255: ACTION_NONE, so at most 255 actions)
GYMNASIUM_MAX_STEPS = 500  # CartPole-v1 truncates an episode at 500 steps
INTEGRATORS = ("semi_implicit", "euler")
TIE_BREAKS = ("exact", "index", "random")
TAGGING = ("winner", "both_neurons")
E_FLAGS = ("latched", "live")
SUCCESS_COUNTER = ("per_trial", "carry")
DECAY_COUNTERS = ("per_trial", "carry")
FIRST_ACTION = ("infer", "no_force")
PUNISH_TIMING = ("before_decay", "after_decay")
INFERENCE = ("ceiled", "exact")
ANGLE_EDGES_DEG = (-6.0, -1.0, 0.0, 1.0, 6.0)  # Table 1 interior angle edges, deg
# The cart-pole state, in the order of the state vector (x, x_dot, theta, theta_dot).
STATE_NAMES = ("cart_position", "cart_velocity", "pole_angle", "pole_angular_velocity")
# The encoded state variables for nsv = 1, 2, 3, 4 (the paper's two first, its Table 1 order).
STATE_VAR_ORDER = ("pole_angle", "cart_velocity", "cart_position", "pole_angular_velocity")
EDGE_FIELDS = ("angle_edges_deg", "position_edges_m", "angular_velocity_edges_deg_per_s")


MAX_SEGMENTS = 256  # Action.winning_segment is a uint8


class ParamError(ValueError):
    """A bad parameter value; its message is one line meant for the user."""


@dataclass(frozen=True)
class Params:
    """All model parameters. Defaults: Table 2 and section 3 of the paper, `paper` conventions."""

    # The task (core.task): "cartpole" (the paper's, every physics below), or another task's
    # name, e.g. "gymnasium:Acrobot-v1": its variables' edges are then variable_edges, and the
    # cart-pole's own values (physics, limits, the paper's protocol) do not apply.
    task: str = CARTPOLE
    n_actions: int = 2  # one RLN per action (the cart-pole's: -F, +F)
    reward_mapping: str = "failure"  # REWARD_MAPPINGS

    # Network and learning (section 3.2 and Table 2).
    nsv: int | None = None  # how many state variables are encoded; None: len(state_vars), or 1
    # Which, in input order (a tuple, or text "pole_angle,cart_velocity"); None: the first nsv of
    # STATE_VAR_ORDER (1 = angle, 2 = angle + cart velocity, as in the paper).
    state_vars: tuple | None = None
    # Segments per neuron; None: half the number of input combinations, rounded up (the paper's
    # 3 for 1 SV, 6 intervals, and 9 for 2 SV, 6 x 3 combinations).
    segments: int | None = None
    sigma: int = 256  # success window: positive reward every sigma successful steps
    omega: int = 256  # punishment window: length of the action path punished on failure
    rho_plus: float = 1 / 128  # maximum reward capture (synapses whose e flag is 1)
    rho_minus: float = 7 / 1024  # maximum reward backoff (synapses whose e flag is 0)
    punish: float = 8 / 1024  # pi: maximum punishment decrement
    w_max: float = 8.0
    w_base: float = 4.5
    w_range: float = 1 / 128

    # Protocol (section 3.2).
    trials: int = 512
    max_steps: int = 10_000  # a trial stops after this many successful steps
    n_angles: int = 32  # initial angles evenly spaced over [-angle_span_deg, +angle_span_deg]
    angle_span_deg: float = 1.5
    # "paper": the above; "gymnasium": CartPole-v1's own protocol, as the RL field measures
    # agents: each trial starts where Gymnasium's reset() puts it (all four variables uniform in
    # +-0.05, SI units and radians; core.episode.trial_starts) and is truncated at 500 steps.
    protocol: str = "paper"

    # Encoder (Table 1): interior interval edges. A tuple, or text "-6,-1,0,1,6" (ROS/YAML).
    angle_edges_deg: tuple = ANGLE_EDGES_DEG  # pole angle, deg: len + 1 inputs (Table 1: 6)
    velocity_edge: float = 5.0  # |dx/dt| edge between the 3 velocity intervals, m/s
    # Not in the paper (its way forward): thirds of the track, and the median |theta_dot| of the
    # Figure 7 weights' trials under the paper's physics.
    position_edges_m: tuple = (-0.8, 0.8)
    angular_velocity_edges_deg_per_s: tuple = (-3.0, 3.0)
    # Any other task's variables: ((name, (edges...)), ...), or text "name:e1,e2;name2:e1" (ROS).
    variable_edges: tuple = ()

    # Environment (section 1.2).
    physics: str = "paper"  # "paper": the units slip that reproduces the figures; "correct": true equations
    # ("gymnasium": CartPole-v1's step itself, its float operations in its order, in radians)
    integrator: str = "semi_implicit"  # "semi_implicit" (velocities first) or "euler" (explicit)
    cart_mass: float = 0.711
    pole_mass: float = 0.209
    pole_length: float = 0.326
    gravity: float = 9.8
    force: float = 10.0
    tau: float = 0.02
    angle_limit_deg: float = 12.0
    track_limit_m: float = 2.4

    # Open choices of the learning rule (see the conventions in docs/REPRODUCTION.md).
    tie_break: str = "exact"  # WTA tie: "exact" un-ceiled sums then lowest index, "index", "random"
    tagging: str = "winner"  # tag only the action path ("winner") or the winning segment of both neurons
    e_flag: str = "latched"  # e flag latched at tagging ("latched") or read at reward time ("live")
    success_counter: str = "per_trial"  # success counter reset each trial ("per_trial") or kept ("carry")
    decay_counters: str = "per_trial"  # decay counters and e flags reset each trial, or kept ("carry")
    first_action: str = "infer"  # the network acts on the initial state, or "no_force": the pole
    # is released with F = 0 for one step first (not a successful step: the network did not act)
    punish_timing: str = "before_decay"  # the path's head gets c- = omega, or omega - 1 ("after_decay")
    inference: str = "ceiled"  # segment response: sum of ceil(w) ("ceiled") or of w ("exact")
    # A way out of local optima (not in the paper): the network WTA's winner is overruled with
    # this probability and the other neuron acts (its winning segment is the path's).
    explore: float = 0.0
    # The paper's section 5 proposal (not in its model): at the start of every
    # rerandomize_every-th trial (0: never), each synapse is re-drawn with probability
    # rerandomize_fraction, to w_base + uniform [0, rerandomize_range).
    rerandomize_every: int = 0
    rerandomize_fraction: float = 0.01
    rerandomize_range: float = 1 / 128

    # Derived values; not set by users.
    n_inputs: int = field(init=False)
    n_segments: int = field(init=False)

    def __post_init__(self) -> None:
        for name in EDGE_FIELDS:
            object.__setattr__(self, name, parse_edges(getattr(self, name), name))
        object.__setattr__(self, "variable_edges", parse_variable_edges(self.variable_edges))
        names = resolve_state_vars(self.state_vars, self.nsv,
                                   tuple(name for name, _ in self.variable_edges))
        object.__setattr__(self, "state_vars", names)
        object.__setattr__(self, "nsv", len(names))
        self.validate()
        intervals = [len(self.edges_of(v)) + 1 for v in names]
        object.__setattr__(self, "n_inputs", sum(intervals))
        # half the input combinations, rounded up; another task's (many variables) at most
        # what the messages carry
        half = -(-math.prod(intervals) // 2)
        object.__setattr__(self, "n_segments", self.segments or
                           (half if self.task == CARTPOLE else min(half, MAX_SEGMENTS)))

    def edges_of(self, state_var: str) -> tuple[float, ...]:
        """The interior interval edges of a state variable, in its unit."""
        if state_var not in STATE_NAMES:
            return dict(self.variable_edges)[state_var]
        if state_var == "cart_velocity":
            return (-self.velocity_edge, self.velocity_edge)
        return {"pole_angle": self.angle_edges_deg, "cart_position": self.position_edges_m,
                "pole_angular_velocity": self.angular_velocity_edges_deg_per_s}[state_var]

    def validate(self) -> None:
        """Raise ParamError with one clear line for the first bad value found."""
        _choice("physics", self.physics, PHYSICS)
        _choice("protocol", self.protocol, PROTOCOLS)
        _choice("integrator", self.integrator, INTEGRATORS)
        _choice("tie_break", self.tie_break, TIE_BREAKS)
        _choice("tagging", self.tagging, TAGGING)
        _choice("e_flag", self.e_flag, E_FLAGS)
        _choice("success_counter", self.success_counter, SUCCESS_COUNTER)
        _choice("decay_counters", self.decay_counters, DECAY_COUNTERS)
        _choice("first_action", self.first_action, FIRST_ACTION)
        _choice("punish_timing", self.punish_timing, PUNISH_TIMING)
        _choice("inference", self.inference, INFERENCE)
        _choice("reward_mapping", self.reward_mapping, REWARD_MAPPINGS)
        if self.reward_mapping == "shaped" and self.success_counter != "per_trial":
            raise ParamError("reward_mapping shaped sums each trial's own rewards: "
                             "success_counter must be per_trial")
        if self.reward_mapping == "shaped" and self.task == CARTPOLE:
            raise ParamError("reward_mapping shaped reads a task's rewards, and the cart-pole's "
                             "are the same on every step: use failure")
        if not isinstance(self.task, str) or not self.task.strip():
            raise ParamError(f"task must be a task's name, e.g. {CARTPOLE!r}, got {self.task!r}")
        if isinstance(self.n_actions, bool) or not isinstance(self.n_actions, int) \
                or not 2 <= self.n_actions <= MAX_ACTIONS:
            raise ParamError(f"n_actions must be an integer from 2 to {MAX_ACTIONS}, "
                             f"got {self.n_actions!r}")
        if self.task == CARTPOLE and self.n_actions != 2:
            raise ParamError(f"the cart-pole has 2 actions (-F, +F): n_actions must be 2, "
                             f"got {self.n_actions!r}")
        segments = self.segments
        if segments is not None and (isinstance(segments, bool) or not isinstance(segments, int)
                                     or not 1 <= segments <= MAX_SEGMENTS):
            raise ParamError(f"segments must be an integer from 1 to {MAX_SEGMENTS}, "
                             f"got {segments!r}")
        if isinstance(self.rerandomize_every, bool) or not isinstance(self.rerandomize_every, int) \
                or not 0 <= self.rerandomize_every < 2**31:
            raise ParamError(f"rerandomize_every must be an integer from 0 (never) to 2**31 - 1, "
                             f"got {self.rerandomize_every!r}")
        for name in ("sigma", "omega", "trials", "max_steps", "n_angles"):
            value = getattr(self, name)
            # Counts travel in the messages' uint32 fields (trial, successful_steps).
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value < 2**31:
                raise ParamError(f"{name} must be a positive integer below 2**31, got {value!r}")
        if self.task == CARTPOLE and self.protocol == "gymnasium" and \
                self.max_steps != GYMNASIUM_MAX_STEPS:
            raise ParamError(f"protocol gymnasium truncates a trial at {GYMNASIUM_MAX_STEPS} steps "
                             f"(CartPole-v1): max_steps must be {GYMNASIUM_MAX_STEPS}, got "
                             f"{self.max_steps!r}")
        positive = ("w_max", "cart_mass", "pole_mass", "pole_length", "gravity", "tau",
                    "angle_limit_deg", "track_limit_m", "velocity_edge")
        non_negative = ("rho_plus", "rho_minus", "punish", "w_base", "w_range", "force",
                        "angle_span_deg", "explore", "rerandomize_fraction", "rerandomize_range")
        for name in positive + non_negative:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ParamError(f"{name} must be a finite number, got {value!r}")
            if name in positive and value <= 0:
                raise ParamError(f"{name} must be > 0, got {value!r}")
            if value < 0:
                raise ParamError(f"{name} must be >= 0, got {value!r}")
        if not 0 <= self.explore <= 1:
            raise ParamError(f"explore must be a probability from 0 to 1, got {self.explore!r}")
        if not 0 <= self.rerandomize_fraction <= 1:
            raise ParamError(f"rerandomize_fraction must be a probability from 0 to 1, "
                             f"got {self.rerandomize_fraction!r}")
        if self.w_base + self.w_range > self.w_max:
            raise ParamError(f"w_base + w_range ({self.w_base + self.w_range:g}) must not exceed "
                             f"w_max ({self.w_max:g})")
        if self.w_base + self.rerandomize_range > self.w_max:
            raise ParamError(f"w_base + rerandomize_range ({self.w_base + self.rerandomize_range:g})"
                             f" must not exceed w_max ({self.w_max:g})")
        if self.angle_limit_deg > 12.0:
            raise ParamError(f"angle_limit_deg must be <= 12 (Table 1 encodes only [-12, 12)), "
                             f"got {self.angle_limit_deg!r}")
        if self.angle_span_deg >= self.angle_limit_deg:
            raise ParamError(f"angle_span_deg ({self.angle_span_deg:g}) must be below "
                             f"angle_limit_deg ({self.angle_limit_deg:g})")
        for name, edges in [*((n, getattr(self, n)) for n in EDGE_FIELDS),
                            *((f"variable_edges of {n}", e) for n, e in self.variable_edges)]:
            if any(b <= a for a, b in zip(edges, edges[1:])):
                raise ParamError(f"{name} must be strictly increasing, got {list(edges)}")
        edges = self.angle_edges_deg
        if not all(abs(e) < self.angle_limit_deg for e in edges):
            raise ParamError(f"angle_edges_deg must lie inside +-angle_limit_deg "
                             f"({self.angle_limit_deg:g}), got {list(edges)}")

    def replace(self, **changes) -> "Params":
        """A copy with some values changed (validated again)."""
        current = {f.name: getattr(self, f.name) for f in fields(self) if f.init}
        unknown = set(changes) - set(current)
        if unknown:
            raise ParamError(f"unknown parameter(s): {', '.join(sorted(unknown))}; "
                             f"known: {', '.join(sorted(current))}")
        # nsv and state_vars say the same thing: a change of one alone decides both
        if "state_vars" in changes and "nsv" not in changes:
            current["nsv"] = None
        if "nsv" in changes and "state_vars" not in changes:
            current["state_vars"] = None
        return Params(**{**current, **changes})

    def to_dict(self) -> dict:
        """The user-settable values (what replace() and Params(**d) accept)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.init}


def _choice(name: str, value, allowed: tuple, meaning: str | None = None) -> None:
    if isinstance(value, bool) or value not in allowed:
        options = ", ".join(repr(a) for a in allowed)
        raise ParamError(f"{name} must be one of {options}" + (f" ({meaning})" if meaning else "")
                         + f", got {value!r}")


def _items(value) -> list | tuple:
    """The items of a list given as a tuple/list or as text "a,b" (brackets allowed)."""
    if isinstance(value, str):
        text = value.strip().removeprefix("[").removesuffix("]")
        return [t.strip("'\"") for t in text.replace(" ", ",").split(",") if t]
    return value


def parse_edges(value, name: str = "angle_edges_deg") -> tuple[float, ...]:
    """Interior interval edges from a tuple/list of numbers or text "-6,-1,0,1,6": a tuple of
    at least one finite float, else one ParamError line."""
    items = _items(value)
    try:
        if not isinstance(items, (list, tuple)) or any(isinstance(e, bool) for e in items):
            raise ValueError
        edges = tuple(float(e) for e in items)
    except (TypeError, ValueError):
        raise ParamError(f"{name} must be numbers separated by commas, got {value!r}") from None
    if not edges or not all(math.isfinite(e) for e in edges):
        raise ParamError(f"{name} must be one or more finite numbers, got {value!r}")
    return edges


def parse_variable_edges(value) -> tuple[tuple[str, tuple[float, ...]], ...]:
    """Other tasks' variables and their interior edges, from ((name, edges), ...) or text
    "name:e1,e2;name2:e1": a tuple of (name, edges), else one ParamError line."""
    if isinstance(value, str):
        pairs = []
        for part in (p.strip() for p in value.split(";") if value.strip()):
            name, colon, edges = part.partition(":")
            if not colon:
                raise ParamError(f"variable_edges must be name:edges separated by ';', e.g. "
                                 f"'x:-1,0,1;v:0', got {value!r}")
            pairs.append((name.strip(), edges))
        value = pairs
    try:
        pairs = tuple((name, edges) for name, edges in value)
    except (TypeError, ValueError):
        raise ParamError(f"variable_edges must be (name, edges) pairs, got {value!r}") from None
    names = [name for name, _ in pairs]
    for name in names:
        if not isinstance(name, str) or not name.isidentifier():
            raise ParamError(f"variable_edges: a variable's name must be a word of letters, "
                             f"digits and _, got {name!r}")
        if name in STATE_NAMES:
            raise ParamError(f"variable_edges: {name} is a cart-pole variable, whose edges are "
                             f"its own parameter (e.g. angle_edges_deg)")
        if names.count(name) > 1:
            raise ParamError(f"variable_edges names {name} twice")
    return tuple((name, parse_edges(edges, f"variable_edges of {name}")) for name, edges in pairs)


def variable_edges_text(pairs: tuple) -> str:
    """variable_edges as text, "name:e1,e2;name2:e1" ("" for none): what parse_variable_edges
    takes, and a ROS parameter can hold (it has no list of lists)."""
    return ";".join(f"{name}:{','.join(repr(e) for e in edges)}" for name, edges in pairs)


def resolve_state_vars(value, nsv, other_names: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The encoded state variables from state_vars (names, or text "a,b") and nsv; one
    ParamError line for unknown or repeated names, or an nsv that does not match. Known names:
    the cart-pole's and `other_names` (another task's, with edges in variable_edges)."""
    if value is None and nsv is not None and (isinstance(nsv, bool) or nsv not in range(1, 5)):
        raise ParamError(f"nsv must be 1, 2, 3 or 4 (state variables encoded), got {nsv!r}")
    if value is None:
        return STATE_VAR_ORDER[:nsv or 1]
    items = _items(value)
    if not isinstance(items, (list, tuple)) or not items or \
            not all(isinstance(v, str) for v in items):
        raise ParamError(f"state_vars must be names separated by commas, got {value!r}")
    names = tuple(items)
    known = (*STATE_NAMES, *other_names)
    unknown = [v for v in names if v not in known]
    if unknown:
        raise ParamError(f"state_vars: unknown {unknown[0]!r}; known: {', '.join(known)} "
                         f"(another task's variables need their edges in variable_edges)")
    if len(set(names)) != len(names):
        raise ParamError(f"state_vars names a variable twice: {','.join(names)}")
    if nsv is not None and (isinstance(nsv, bool) or nsv != len(names)):
        raise ParamError(f"nsv ({nsv}) must be the number of state_vars ({len(names)}: "
                         f"{','.join(names)}), or not given")
    return names


def protocol_defaults(values: dict) -> dict:
    """values (by name, as text or typed) with what their protocol implies where they leave it
    open: CartPole-v1's truncation at 500 steps under protocol gymnasium."""
    if values.get("protocol") == "gymnasium" and "max_steps" not in values:
        return {**values, "max_steps": GYMNASIUM_MAX_STEPS}
    return values


def params_from_strings(values: dict[str, str], base: Params | None = None) -> Params:
    """Params from text values (command line, ROS parameters, YAML), each converted to the
    type of its field; a value that does not convert is one clear ParamError line."""
    base = base or Params()
    current = base.to_dict()
    converted = {}
    for name, text in values.items():
        if name not in current:
            raise ParamError(f"unknown parameter {name!r}; known: {', '.join(sorted(current))}")
        default = current[name]
        kind = int if name in ("segments", "nsv") or isinstance(default, int) else type(default)
        try:
            if kind is tuple or name == "state_vars":
                converted[name] = text  # Params parses and validates it
            elif isinstance(text, kind) and not isinstance(text, bool):
                converted[name] = text
            elif kind is int:
                converted[name] = int(str(text), 10)
            elif kind is float:
                converted[name] = float(str(text))
            else:
                converted[name] = str(text)
        except ValueError:
            raise ParamError(f"{name} must be {'an integer' if kind is int else 'a number'}, "
                             f"got {text!r}") from None
    return base.replace(**converted)


__all__ = ["Params", "ParamError", "params_from_strings", "protocol_defaults", "PHYSICS",
           "PROTOCOLS", "REWARD_MAPPINGS", "CARTPOLE", "MAX_ACTIONS",
           "GYMNASIUM_MAX_STEPS", "INTEGRATORS", "TIE_BREAKS",
           "TAGGING", "E_FLAGS", "SUCCESS_COUNTER", "DECAY_COUNTERS", "FIRST_ACTION",
           "PUNISH_TIMING", "INFERENCE", "STATE_NAMES", "STATE_VAR_ORDER"]
