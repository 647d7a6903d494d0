"""The content rules of the graph's topics: what every subscriber of a topic refuses, whoever
sent it and whatever the node's state. Each rule returns the reason to refuse a message, or None.
A node applies its topic's rule (RULES) to every message first; then come the sender and the
tick (docs/ROS_GRAPH.md, "What a node refuses"). A rule reads only the parameters its topic's
subscribers take (graph.run.NODE_PARAMETERS)."""

from __future__ import annotations

import math

from ..core.params import Params
from ..core.rln import KIND_OF_CODE
from .fields import EPISODE_END, END, FAILURE_NONE, FAILURE_REASONS, START
from .names import ACTION, CLOCK, REWARD, SPIKES, STATE, TRIAL_EVENT, WEIGHTS

N_NEURONS = 2  # the agent's two RLNs: negative and positive force
EVENT_KINDS = (START, END, EPISODE_END)
# A simulator's limit check may differ from the message's degrees in the last bits (gymnasium
# works in radians): a state that did not fail may lie this far beyond a limit.
LIMIT_TOLERANCE = 1e-6


def clock_problem(msg, p: Params) -> str | None:
    if msg.clock.nanosec >= 1_000_000_000:
        return f"nanosec {msg.clock.nanosec} is not below one second"
    nanoseconds = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
    if nanoseconds % round(p.tau * 1e9):
        return f"sim time {msg.clock.sec}.{msg.clock.nanosec:09d} s is not a whole tick"
    return None


def event_problem(msg, p: Params) -> str | None:
    if msg.event not in EVENT_KINDS:
        return f"unknown event kind {msg.event}"
    if msg.event == START and not abs(msg.initial_angle_deg) < p.angle_limit_deg:
        return f"START's initial angle {msg.initial_angle_deg} is not inside " \
               f"+-{p.angle_limit_deg} deg"
    return None


def state_problem(msg, p: Params) -> str | None:
    values = (msg.cart_position_m, msg.cart_velocity_m_per_s, msg.pole_angle_deg,
              msg.pole_angular_velocity_deg_per_s)
    if not all(math.isfinite(v) for v in values):
        return f"non-finite state {values}"
    if msg.successful_steps > p.max_steps:
        return f"{msg.successful_steps} successful steps, more than max_steps {p.max_steps}"
    if msg.failure >= len(FAILURE_REASONS):
        return f"failure {msg.failure} is not one of CartPoleState's FAILURE_* codes"
    if msg.failure == FAILURE_NONE and (
            abs(msg.pole_angle_deg) > p.angle_limit_deg + LIMIT_TOLERANCE or
            abs(msg.cart_position_m) > p.track_limit_m + LIMIT_TOLERANCE):
        return f"out of range: pole angle {msg.pole_angle_deg} deg, cart position " \
               f"{msg.cart_position_m} m, but not failed"
    return None


def spikes_problem(msg, p: Params) -> str | None:
    spikes = msg.spikes
    if len(spikes) != p.n_inputs:
        return f"{len(spikes)} spikes, the network has {p.n_inputs} inputs"
    if max(spikes, default=0) > 1 or sum(spikes) != p.nsv:
        return f"not a 1-hot code per state variable: {list(spikes)}"
    return None


def reward_problem(msg, _p: Params) -> str | None:
    if tuple(msg.reward_one_hot.tolist()) not in KIND_OF_CODE:
        return f"code {msg.reward_one_hot.tolist()} is not [0, 0], [1, 0] or [0, 1]"
    return None


def action_problem(msg, p: Params) -> str | None:
    if msg.force_direction not in (-1, 0, 1):
        return f"force_direction {msg.force_direction} is not -1, 0 or 1"
    if msg.force_n != msg.force_direction * p.force:
        return f"force_n {msg.force_n} is not force_direction x force ({p.force:g} N)"
    if msg.winning_neuron >= N_NEURONS or msg.winning_segment >= p.n_segments:
        return f"winning neuron {msg.winning_neuron} / segment {msg.winning_segment} does not " \
               f"exist ({N_NEURONS} neurons x {p.n_segments} segments)"
    return None


def weights_problem(msg, p: Params) -> str | None:
    shape = (N_NEURONS, p.n_segments, p.n_inputs)
    if (msg.neurons, msg.segments, msg.inputs) != shape or len(msg.weights) != math.prod(shape):
        return f"{len(msg.weights)} weights of shape {(msg.neurons, msg.segments, msg.inputs)}, " \
               f"the network is {shape}"
    if not all(0.0 <= w <= p.w_max for w in msg.weights):  # False for NaN too
        return f"weights outside [0, w_max={p.w_max:g}]"
    return None


# Each topic's rule.
RULES = {CLOCK: clock_problem, TRIAL_EVENT: event_problem, STATE: state_problem,
         SPIKES: spikes_problem, REWARD: reward_problem, ACTION: action_problem,
         WEIGHTS: weights_problem}
