"""Reinforcement-learning neurons (RLNs) and the three-factor learning rules, sections 2.2-2.3.

One RLN per action of the task (K >= 2; the paper's cart-pole has two: neuron 0 drives -F and
neuron 1 drives +F). Each has one dendrite of q segments; each segment has one synapse per
encoder input. The per-synapse state is that of the paper's Figures 5 and 6: decay counters
(each kept as the tick at which it was set, see below) and e flags.

Inference (every tick, section 2.2):
    segment response = sum over spiking inputs of ceil(w)      (small-integer inference;
                                                                inference="exact": of w)
    dendrite WTA picks each neuron's best segment, network WTA over the K neurons picks the
    neuron (the action).
    Ties (all initial weights ceil to 5) are broken by the exact un-ceiled sums, then the lowest
    index (`tie_break="exact"`); "index" skips the exact sums, "random" picks among the tied.

Tagging (the action path, section 2.3): the winning segment of the winning neuron. Its spiking
synapses get the punishment decay counter c- = omega; the segment gets the reward counter
c+ = sigma and each of its synapses an e flag latched now (1 if its input spiked).

Update, after the environment step (section 2.3, Figure 6):
    punishment (failure):   w -= pi * c- / omega            for every synapse with c- > 0
                            (punish_timing="after_decay": the counters decay first)
    reward (every sigma-th success):
                            w += rho+ * c+ / sigma  if e = 1,  w -= rho- * c+ / sigma  if e = 0,
                            for every synapse of every segment with c+ > 0
    then every counter decays by one; weights are clipped to [0, w_max]. A trial starts with
    every decay counter and e flag at 0 (decay_counters="carry": as the last trial left them).

The rule is written once, as the functions below (`jitable`: plain Python when called
from Python, compiled into the numba batch engine, clnn_ros.batch, which calls the same
functions). Every option of the rule (tie_break, inference, tagging, e_flag, punish_timing,
decay_counters, success_counter, rerandomize_*) is decided here and nowhere else; core.rule
holds their values (Rule) and the reward kinds. The classes of core.agent hold the state and
call them, tick by tick.
"""

from __future__ import annotations

import math

import numpy as np

from .jitable import jitable, kernel, tick_kernel
from .params import Params
from .random_stream import next_uniform
# The rule's constants and options, as numbers (also imported from here by the rest)
from .rule import (KIND_OF_CODE, NONE, ONE_HOT, PUNISH, REWARD, REWARD_KINDS, TIE_EXACT, TIE_RANDOM,
                   Rule)


# ---- inference (section 2.2) -------------------------------------------------------------------

@kernel
def segment_response(weights, neuron, segment, active, ceil):
    """(response, sum of w) over the synapses of the spiking inputs `active` (indices): the
    response is the small-integer sum of ceil(w) (or with `ceil` False the exact one), the exact
    sum can break its ties."""
    response = 0.0
    exact = 0.0
    for i in active:
        w = weights[neuron, segment, i]
        response += math.ceil(w) if ceil else w
        exact += w
    return response, exact


@kernel
def wta(ceiled, exact, count, tie_break, random_state):
    """Winner-take-all among candidates 0..count-1 with responses ceiled[k] (exact[k]): the
    largest ceiled response; a tie is broken by the option tie_break (draws from random_state)."""
    best, tied = 0, 1
    for k in range(1, count):
        if ceiled[k] > ceiled[best]:
            best, tied = k, 1
        elif ceiled[k] == ceiled[best]:
            tied += 1
            if tie_break == TIE_EXACT and exact[k] > exact[best]:  # strict: lowest index wins
                best = k
    if tied == 1 or tie_break != TIE_RANDOM:
        return best
    pick = int(next_uniform(random_state) * tied)  # the pick-th of the tied, in index order
    for k in range(count):
        if ceiled[k] == ceiled[best]:
            if pick == 0:
                return k
            pick -= 1
    return best


@jitable  # it makes an array: with reference counting
def response_space(n_neurons, n_segments):
    """Scratch space for infer: the ceiled and the exact responses of the WTA's candidates."""
    return np.empty((2, max(n_segments, n_neurons)))


@kernel
def dendrite_winner(weights, neuron, active, rule, random_state, ceiled, exact):
    """The dendrite WTA: the winning segment of one neuron."""
    n_segments = weights.shape[1]
    for s in range(n_segments):
        ceiled[s], exact[s] = segment_response(weights, neuron, s, active, rule.ceiled)
    return wta(ceiled, exact, n_segments, rule.tie_break, random_state)


@kernel
def infer(weights, active, rule, random_state, responses, segments):
    """The winning neuron for the spiking inputs `active`: the dendrite WTA within each neuron
    (its winner written to segments[neuron]), then the network WTA among the neurons.
    `responses`: scratch space from response_space()."""
    ceiled, exact = responses[0], responses[1]
    n_neurons = weights.shape[0]
    for n in range(n_neurons):
        segments[n] = dendrite_winner(weights, n, active, rule, random_state, ceiled, exact)
    for n in range(n_neurons):
        ceiled[n], exact[n] = segment_response(weights, n, segments[n], active, rule.ceiled)
    return wta(ceiled, exact, n_neurons, rule.tie_break, random_state)


@tick_kernel
def explore(neuron, n_neurons, rule, random_state):
    """The neuron that acts: the network WTA's winner, or with probability rule.explore another
    one (a draw on every tick only when exploring; with more than two neurons a second draw
    picks which of the others, each as likely)."""
    if rule.explore > 0.0 and next_uniform(random_state) < rule.explore:
        if n_neurons == 2:
            return 1 - neuron
        other = int(next_uniform(random_state) * (n_neurons - 1))
        return other + 1 if other >= neuron else other
    return neuron


# ---- decay counters (Figures 5 and 6) ---------------------------------------------------------
# A counter is set to its window (omega or sigma) at tagging and decays by one every tick, down
# to 0. It is kept as the tick at which it was set: its value at tick `now` is
# max(window - (now - tagged_at), 0). That is the same number, and "every counter decays by one"
# is the clock advancing by one tick instead of a pass over every synapse on every tick.

NEVER = -(2**62)  # the tick of a counter not set in this trial: its value is 0


@kernel
def counter_value(tagged_at, now, window):
    """The value at tick `now` of a decay counter set to `window` at tick `tagged_at` (an array of
    ticks gives an array of values)."""
    return np.maximum(window - (now - tagged_at), 0)


@kernel
def restart_counters(punish_tagged_at, reward_tagged_at, eligible, rule):
    """A trial starts with every decay counter and e flag at 0 (decay_counters="carry": as the
    last trial left them)."""
    if rule.decay_per_trial:
        punish_tagged_at[:] = NEVER
        reward_tagged_at[:] = NEVER
        eligible[:] = 0


# ---- re-randomization (the paper's section 5 proposal) -----------------------------------------

@kernel
def rerandomize(weights, trial, rule, random_state):
    """At the start of every rerandomize_every-th trial (not the first), each synapse is re-drawn
    with probability rerandomize_fraction to w_base + uniform [0, rerandomize_range): a way out of
    local optima. Returns whether it was the time (the weights may then have changed)."""
    if rule.rerandomize_every == 0 or trial == 0 or trial % rule.rerandomize_every != 0:
        return False
    n_neurons, n_segments, n_inputs = weights.shape
    for n in range(n_neurons):
        for s in range(n_segments):
            for i in range(n_inputs):
                if next_uniform(random_state) < rule.rerandomize_fraction:
                    weights[n, s, i] = rule.w_base + rule.rerandomize_range * next_uniform(
                        random_state)
    return True


# ---- tagging (section 2.3) ---------------------------------------------------------------------

@tick_kernel
def tag_segment(punish_tagged_at, reward_tagged_at, eligible, neuron, segment, active, now):
    """c- = omega on the segment's spiking synapses, c+ = sigma on the segment, e flags latched."""
    eligible[neuron, segment, :] = 0
    for i in active:
        punish_tagged_at[neuron, segment, i] = now
        eligible[neuron, segment, i] = 1
    reward_tagged_at[neuron, segment] = now


@tick_kernel
def tag_action_path(punish_tagged_at, reward_tagged_at, eligible, neuron, segments, active, now,
                    rule):
    """Tag the winning segment of the winning neuron (`segments`: each neuron's dendrite winner,
    an array or a tuple); with tagging="both_neurons" also every other neuron's."""
    if len(segments) == 2:
        # Of two, a choice between two values: compiled, segments[neuron] would be a jump table
        # for a tuple, mispredicted whenever the action changes, or a load that waits for the
        # neuron (the cart-pole's batch engine: a few per cent of its tick).
        winner, other = (segments[1], segments[0]) if neuron == 1 else (segments[0], segments[1])
        tag_segment(punish_tagged_at, reward_tagged_at, eligible, neuron, winner, active, now)
        if rule.tag_both:
            tag_segment(punish_tagged_at, reward_tagged_at, eligible, 1 - neuron, other, active,
                        now)
        return
    tag_segment(punish_tagged_at, reward_tagged_at, eligible, neuron, segments[neuron], active,
                now)
    if rule.tag_both:
        for other in range(len(segments)):
            if other != neuron:
                tag_segment(punish_tagged_at, reward_tagged_at, eligible, other, segments[other],
                            active, now)


# ---- the update after the step (section 2.3, Figure 6) -----------------------------------------

@kernel
def clip_weight(w, w_max):
    """Weights saturate at 0 and w_max."""
    return min(max(w, 0.0), w_max)


@kernel
def punish(weights, punish_tagged_at, now, rule):
    """w -= pi * c- / omega on every synapse with c- > 0 (punish_timing="after_decay": the
    counters' values after this tick's decay)."""
    n_neurons, n_segments, n_inputs = weights.shape
    for n in range(n_neurons):
        for s in range(n_segments):
            for i in range(n_inputs):
                c = counter_value(punish_tagged_at[n, s, i], now + rule.punish_lag, rule.omega)
                if c > 0:
                    weights[n, s, i] = clip_weight(
                        weights[n, s, i] - rule.punish * c / rule.omega, rule.w_max)


@kernel
def reward(weights, reward_tagged_at, eligible, last_active, now, rule):
    """On every segment with c+ > 0: w += rho+ c+ / sigma where e = 1, w -= rho- c+ / sigma where
    e = 0. e is the flag latched at tagging, or with e_flag="live" whether the input spiked on
    the latest tick (`last_active`)."""
    n_neurons, n_segments, n_inputs = weights.shape
    for n in range(n_neurons):
        for s in range(n_segments):
            c = counter_value(reward_tagged_at[n, s], now, rule.sigma)
            if c <= 0:
                continue
            for i in range(n_inputs):
                if rule.e_latched:
                    e = eligible[n, s, i] == 1
                else:
                    e = False
                    for spiking in last_active:
                        e = e or spiking == i
                rate = rule.rho_plus if e else -rule.rho_minus
                weights[n, s, i] = clip_weight(weights[n, s, i] + rate * c / rule.sigma,
                                               rule.w_max)


@tick_kernel
def update(kind, weights, punish_tagged_at, reward_tagged_at, eligible, last_active, now, rule):
    """Apply a reward kind (NONE, REWARD, PUNISH) at tick `now`, then decay every counter by one:
    returns the next tick."""
    if kind == PUNISH:
        punish(weights, punish_tagged_at, now, rule)
    elif kind == REWARD:
        reward(weights, reward_tagged_at, eligible, last_active, now, rule)
    return now + 1


# ---- the success counter: the paper's 1-hot reward R (section 2.3) -----------------------------

@tick_kernel
def trial_start_count(count, rule):
    """The success count a trial starts with: 0, or with success_counter="carry" the count
    so far."""
    return 0 if rule.counter_per_trial else count


@tick_kernel
def outcome(count, terminated, rule):
    """(reward kind, new success count) for a step's outcome. The paper's mapping (a task that
    terminates in failure): PUNISH when the step terminated the episode, REWARD on every
    sigma-th success (the count then restarts), NONE otherwise. reward_mapping="goal" (a task
    that terminates in success): REWARD when it terminated, PUNISH on every omega-th step
    without it (the count then restarts)."""
    if rule.reward_on_goal:
        if terminated:
            return REWARD, count
        count += 1
        if count == rule.omega:
            return PUNISH, 0
        return NONE, count
    if terminated:
        return PUNISH, count
    count += 1
    if count == rule.sigma:
        return REWARD, 0
    return NONE, count


@tick_kernel
def task_outcome(count, window, terminated, reward, rule):
    """(reward kind, new count, new window) for a step of a task that gives a reward each
    step: outcome()'s, or with reward_mapping="shaped" (a task whose rewards say how well it
    goes): the window sums the rewards of the steps since the last signal; a step that
    terminates the episode REWARDs if it is positive and PUNISHes otherwise, and every sigma-th
    step REWARDs if it is positive and PUNISHes if it is negative; then both restart."""
    if rule.reward_shaped:
        window += reward
        count += 1
        if terminated or count == rule.sigma:
            if window > 0:
                return REWARD, 0, 0.0
            if window < 0 or terminated:
                return PUNISH, 0, 0.0
            return NONE, 0, 0.0
        return NONE, count, window
    kind, count = outcome(count, terminated, rule)
    return kind, count, window
