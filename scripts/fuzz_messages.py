"""The fuzz messages of scripts/fuzz_graph.py: the categories of each input topic and a maker
that builds a message of a category for the live tick. Every message is of one category, and
every subscriber of its topic refuses it (graph.lockstep.Refusals counts the refusals by topic
and kind):

  malformed, refused for its content (kind "content", graph.content), whatever its tick (t):
    non-finite or out-of-range states or unknown failure codes, wrong-sized or not 1-hot spike
    vectors, reward codes that are not 1-hot, out-of-range or inconsistent actions or winners
    that do not exist, wrong-sized or out-of-range weights, unknown event kinds or STARTs
    outside the angle limit, clocks between two ticks or with nanosec >= 1e9;
  well-formed, refused for its tick (kind "tick"):
    stale_tick     a tick 0..t-STALE (sent only from t >= STALE_FROM), behind every
                   subscriber: the trial manager published clock(t) only once every node had
                   finished tick t-1. What a node takes late comes within a tick or two, far
                   less than STALE: the environment holds a trial's force-0 action of tick L
                   before it publishes state(L+2) (one writer's actions come in order), the
                   trial manager's spikes and rewards trail its actions, and its weights of L
                   follow action(L);
    far_tick       a tick t+FAR..the last one /clock can carry (its sec is int32), that an
                   episode never reaches (512 trials of 10,000 steps are 5.1 M ticks);
    foreign_graph  the messages another graph on the same domain and namespace would send: an
                   episode at a phase of FAR..2*FAR ticks ahead of this one (one phase per run),
                   its ticks t + phase moving with the live tick, its trials counted along.
  On trial/event the well-formed messages are EPISODE_ENDs: every node checks the tick of an
  EPISODE_END (graph.lockstep.episode_end_problem: the node's current tick or the one before),
  only the environment acts on START (at the tick after a trial end, checked there) and no node
  on END, so a well-formed START or END of another tick is not refused by every subscriber.
"""

from __future__ import annotations

import math
import random

from clnn_ros_msgs.msg import (Action, CartPoleState, Reward, SpikeVector, TrialEvent,
                               WeightSnapshot)
from rosgraph_msgs.msg import Clock

from clnn_ros.core.params import Params
from clnn_ros.core.rln import ONE_HOT
from clnn_ros.graph.content import N_NEURONS
from clnn_ros.graph.fields import (FAILURE_CART_POSITION, FAILURE_POLE_ANGLE, FAILURE_REASONS,
                                   NANOSECONDS, stamp_nanoseconds, tick_nanoseconds)
from clnn_ros.graph.names import ACTION, CLOCK, REWARD, SPIKES, STATE, TRIAL_EVENT, WEIGHTS

TYPES = {CLOCK: Clock, TRIAL_EVENT: TrialEvent, STATE: CartPoleState, SPIKES: SpikeVector,
         REWARD: Reward, ACTION: Action, WEIGHTS: WeightSnapshot}
WELL_FORMED = ("stale_tick", "far_tick", "foreign_graph")
MALFORMED = {CLOCK: ("between_ticks", "nanosec_overflow"),
             TRIAL_EVENT: ("unknown_kind", "non_finite_angle", "angle_out_of_range"),
             STATE: ("non_finite", "out_of_range", "unknown_failure"),
             SPIKES: ("wrong_size", "not_one_hot"),
             REWARD: ("both_lines", "not_binary"),
             ACTION: ("out_of_range", "non_finite_force", "inconsistent_force", "no_such_neuron"),
             WEIGHTS: ("wrong_size", "non_finite", "out_of_range")}
STALE = 5  # a stale tick is at least this far behind the live tick
STALE_FROM = 10  # stale ticks are sent from this live tick on
FAR = 10_000_000  # a far or foreign tick is at least this far ahead of the live tick
NON_FINITE = (math.nan, math.inf, -math.inf)
INT32_MAX = 2**31 - 1  # builtin_interfaces/Time.sec: a stamp's seconds


class MessageMaker:
    """Builds the fuzz messages of one network (Params) from one random stream."""

    def __init__(self, p: Params, rng: random.Random):
        self.p, self.rng = p, rng
        self.tau_ns = tick_nanoseconds(p.tau)
        self.max_tick = INT32_MAX * NANOSECONDS // self.tau_ns  # the last tick /clock can carry
        self.n_angle_inputs = len(p.angle_edges_deg) + 1
        self.foreign_phase = rng.randint(FAR, 2 * FAR)  # the other graph's lead, in ticks
        self.foreign_trial0 = rng.randint(0, 10_000)

    def make(self, topic: str, category: str, live: int):
        tick = self.tick(category, live)
        msg = getattr(self, "_" + TYPES[topic].__name__)(tick, category)
        if topic != CLOCK:
            msg.tick = tick
            msg.trial = self.foreign_trial0 + tick // (self.p.max_steps + 1) \
                if category == "foreign_graph" else self.rng.randint(0, 50)
        return msg

    def tick(self, category: str, live: int) -> int:
        """The tick a message of `category` carries, for the live tick `live` (the last clock
        of the graph the fuzzer saw); a malformed message carries the live tick itself."""
        rng = self.rng
        if category == "stale_tick":
            return rng.randint(0, live - STALE)
        if category == "far_tick":
            return self.max_tick if rng.random() < 0.1 else rng.randint(live + FAR, self.max_tick)
        if category == "foreign_graph":
            return live + self.foreign_phase
        return live

    def _Clock(self, tick: int, category: str) -> Clock:
        msg = Clock()
        nanoseconds = tick * self.tau_ns
        if category == "between_ticks":
            nanoseconds += self.rng.randint(1, self.tau_ns - 1)
        msg.clock.sec, msg.clock.nanosec = divmod(nanoseconds, NANOSECONDS)
        if category == "nanosec_overflow":
            msg.clock.nanosec = self.rng.randint(NANOSECONDS, 2**32 - 1)
        return msg

    def _TrialEvent(self, _tick: int, category: str) -> TrialEvent:
        rng, limit = self.rng, self.p.angle_limit_deg
        msg = TrialEvent(event=TrialEvent.EPISODE_END, end_reason="completed",
                         successful_steps=rng.randint(0, self.p.max_steps),
                         seed=rng.randint(0, 99))
        if category == "unknown_kind":
            msg.event = rng.randint(3, 255)
        elif category in ("non_finite_angle", "angle_out_of_range"):
            msg.event, msg.successful_steps, msg.end_reason = TrialEvent.START, 0, ""
            msg.initial_angle_deg = rng.choice(NON_FINITE) if category == "non_finite_angle" \
                else rng.choice([-1, 1]) * rng.uniform(limit, 1e6)
        return msg

    def _CartPoleState(self, _tick: int, category: str) -> CartPoleState:
        rng, p = self.rng, self.p
        msg = CartPoleState(cart_position_m=rng.uniform(-0.9, 0.9) * p.track_limit_m,
                            cart_velocity_m_per_s=rng.uniform(-3, 3),
                            pole_angle_deg=rng.uniform(-0.9, 0.9) * p.angle_limit_deg,
                            pole_angular_velocity_deg_per_s=rng.uniform(-100, 100),
                            successful_steps=rng.randint(0, p.max_steps))
        if category in WELL_FORMED and rng.random() < 0.2:  # a trial's failing state
            msg.failure = rng.choice([FAILURE_POLE_ANGLE, FAILURE_CART_POSITION])
            if msg.failure == FAILURE_POLE_ANGLE:
                msg.pole_angle_deg = rng.choice([-1, 1]) * rng.uniform(p.angle_limit_deg, 30)
            else:
                msg.cart_position_m = rng.choice([-1, 1]) * rng.uniform(p.track_limit_m, 3)
        elif category == "non_finite":
            setattr(msg, rng.choice(["cart_position_m", "cart_velocity_m_per_s", "pole_angle_deg",
                                     "pole_angular_velocity_deg_per_s"]), rng.choice(NON_FINITE))
        elif category == "out_of_range":
            which = rng.randrange(3)
            if which == 0:
                msg.pole_angle_deg = rng.choice([-1, 1]) * rng.uniform(p.angle_limit_deg + 0.01,
                                                                       180)
            elif which == 1:
                msg.cart_position_m = rng.choice([-1, 1]) * rng.uniform(p.track_limit_m + 0.01,
                                                                         1e3)
            else:
                msg.successful_steps = p.max_steps + rng.randint(1, 1000)
        elif category == "unknown_failure":
            msg.failure = rng.randint(len(FAILURE_REASONS), 255)
        return msg

    def _SpikeVector(self, _tick: int, category: str) -> SpikeVector:
        rng, n = self.rng, self.p.n_inputs
        spikes = [0] * n
        spikes[rng.randrange(self.n_angle_inputs)] = 1
        if self.p.nsv == 2:
            spikes[self.n_angle_inputs + rng.randrange(n - self.n_angle_inputs)] = 1
        if category == "wrong_size":
            size = rng.choice([k for k in range(0, 3 * n) if k != n])
            spikes = (spikes * 3)[:size]
        elif category == "not_one_hot":
            which = rng.randrange(3)
            if which == 0:
                spikes = [0] * n
            elif which == 1:
                spikes[rng.choice([i for i in range(n) if not spikes[i]])] = 1
            else:
                spikes[spikes.index(1)] = rng.randint(2, 255)
        return SpikeVector(spikes=spikes)

    def _Reward(self, _tick: int, category: str) -> Reward:
        rng = self.rng
        msg = Reward(reward_one_hot=rng.choice(list(ONE_HOT.values())),
                     success_counter=rng.randint(0, 255), trial_over=rng.random() < 0.1)
        if category == "both_lines":  # reward and punishment at once
            msg.reward_one_hot = (1, 1)
        elif category == "not_binary":
            value = rng.randint(2, 255)
            msg.reward_one_hot = rng.choice([(value, 0), (0, value), (value, value)])
        return msg

    def _Action(self, _tick: int, category: str) -> Action:
        rng, p = self.rng, self.p
        # well-formed: -F, +F, or force 0 (the answer to a trial's last state)
        direction = rng.choice([-1, 0, 1]) if category in WELL_FORMED else rng.choice([-1, 1])
        msg = Action(force_direction=direction, force_n=direction * p.force,
                     winning_neuron=int(direction > 0),
                     winning_segment=rng.randrange(p.n_segments) if direction else 0)
        if category == "out_of_range":
            msg.force_direction = rng.choice([-1, 1]) * rng.randint(2, 127)
            msg.force_n = msg.force_direction * p.force
        elif category == "non_finite_force":
            msg.force_n = rng.choice(NON_FINITE)
        elif category == "inconsistent_force":
            msg.force_n += rng.choice([-1, 1]) * rng.uniform(0.5, 5)
        elif category == "no_such_neuron":
            if rng.random() < 0.5:
                msg.winning_neuron = rng.randint(N_NEURONS, 255)
            else:
                msg.winning_segment = rng.randint(p.n_segments, 255)
        return msg

    def _WeightSnapshot(self, _tick: int, category: str) -> WeightSnapshot:
        rng, p = self.rng, self.p
        shape = [N_NEURONS, p.n_segments, p.n_inputs]
        if category == "wrong_size":
            shape[rng.randrange(3)] += rng.choice([-1, 1])
        weights = [rng.uniform(0, p.w_max) for _ in range(math.prod(shape))]
        if category == "wrong_size" and rng.random() < 0.5:  # the right shape, a wrong length
            shape = [N_NEURONS, p.n_segments, p.n_inputs]
        if category == "non_finite":
            weights[rng.randrange(len(weights))] = rng.choice(NON_FINITE)
        elif category == "out_of_range":
            weights[rng.randrange(len(weights))] = rng.choice([-rng.uniform(1e-6, 10),
                                                               p.w_max + rng.uniform(1e-6, 10)])
        return WeightSnapshot(neurons=shape[0], segments=shape[1], inputs=shape[2],
                              weights=weights)


def schedule(per_topic: int, rng: random.Random) -> dict[str, list[str]]:
    """For every topic, the categories of its messages: all of them equally often, shuffled."""
    plan = {}
    for topic in TYPES:
        categories = (*MALFORMED[topic], *WELL_FORMED)
        plan[topic] = [categories[i % len(categories)] for i in range(per_topic)]
        rng.shuffle(plan[topic])
    return plan


def clock_tick(msg: Clock, tau_ns: int) -> int:
    return stamp_nanoseconds(msg.clock.sec, msg.clock.nanosec) // tau_ns
