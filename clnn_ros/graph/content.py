"""The content rules of the graph's topics: what every subscriber of a topic refuses, whoever
sent it and whatever the node's state. Each rule returns the reason to refuse a message, or None.
A node applies its topic's rule (RULES) to every message first; then come the sender and the
tick (docs/ROS_GRAPH.md, "What a node refuses"). A rule reads only the parameters its topic's
subscribers take (graph.run.NODE_PARAMETERS)."""

from __future__ import annotations

import math

from ..core.params import Params
from ..core.rln import KIND_OF_CODE
from .fields import ACTION_NONE, EPISODE_END, END, START
from .names import ACTION, CLOCK, REWARD, SPIKES, STATE, TRIAL_EVENT, WEIGHTS

EVENT_KINDS = (START, END, EPISODE_END)


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


def observation_problem(msg, p: Params) -> str | None:
    """What any observation must be; its count and bounds are its task's (the nodes that read
    the task check them: graph.task_description.Described.observation_problem)."""
    if not all(math.isfinite(v) for v in msg.values) or not math.isfinite(msg.reward):
        return f"non-finite values {list(msg.values)} or reward {msg.reward}"
    if msg.successful_steps > p.max_steps:
        return f"{msg.successful_steps} successful steps, more than max_steps {p.max_steps}"
    if msg.termination and not msg.terminated:
        return f"termination {msg.termination} names a reason, but terminated is false"
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
    if msg.action == ACTION_NONE:
        if msg.winning_segment != 0:
            return f"ACTION_NONE with winning segment {msg.winning_segment}, not 0"
    elif msg.action >= p.n_actions or msg.winning_segment >= p.n_segments:
        return f"action {msg.action} / segment {msg.winning_segment} does not exist " \
               f"({p.n_actions} actions x {p.n_segments} segments)"
    return None


def weights_problem(msg, p: Params) -> str | None:
    shape = (p.n_actions, p.n_segments, p.n_inputs)
    if (msg.neurons, msg.segments, msg.inputs) != shape or len(msg.weights) != math.prod(shape):
        return f"{len(msg.weights)} weights of shape {(msg.neurons, msg.segments, msg.inputs)}, " \
               f"the network is {shape}"
    if not all(0.0 <= w <= p.w_max for w in msg.weights):  # False for NaN too
        return f"weights outside [0, w_max={p.w_max:g}]"
    return None


# Each topic's rule.
RULES = {CLOCK: clock_problem, TRIAL_EVENT: event_problem, STATE: observation_problem,
         SPIKES: spikes_problem, REWARD: reward_problem, ACTION: action_problem,
         WEIGHTS: weights_problem}
