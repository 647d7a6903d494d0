"""The fuzz messages of scripts/fuzz_graph.py: the categories of each input topic and a maker
that builds a message of a category for the live tick. Every message is of one category, and
every subscriber of its topic refuses it (graph.lockstep.Refusals counts the refusals by topic
and kind):

  malformed, refused for its content (kind "content", graph.content), whatever its tick (t):
    observations with a non-finite value or reward, more successful steps than max_steps or a
    termination reason without terminated, wrong-sized or not 1-hot spike vectors, reward codes
    that are not 1-hot, actions or winning segments that do not exist (or ACTION_NONE with a
    segment), wrong-sized or out-of-range weights, unknown event kinds or STARTs outside the
    angle limit, clocks between two ticks or with nanosec >= 1e9 (an observation that does not
    fit its task, by its count, is refused by the encoder alone, which reads the task: not
    sent);
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

env/task (TaskDescription, latched) has no tick: its subscribers (the encoder, the trial
manager) take the first description, before the first tick, and ignore any later one. Its fuzz,
sent while the episode runs, is ignored, not refused: descriptions of another contract version,
of lists that do not pair up, of NaN or inverted bounds, of a task that does not fit the run
(graph.task_description.description_problem refuses each), and the run's own description again.
"""

from __future__ import annotations

import math
import random

from clnn_ros_msgs.msg import (Action, Observation, Reward, SpikeVector, TaskDescription,
                               TrialEvent, WeightSnapshot)
from rosgraph_msgs.msg import Clock

from clnn_ros.core.params import Params
from clnn_ros.core.rln import ONE_HOT
from clnn_ros.graph.content import RULES
from clnn_ros.core.task import cartpole_task
from clnn_ros.graph.fields import (ACTION_NONE, CARTPOLE_TERMINATIONS, NANOSECONDS,
                                   stamp_nanoseconds, tick_nanoseconds)
from clnn_ros.graph.names import (ACTION, CLOCK, REWARD, SPIKES, STATE, TASK, TRIAL_EVENT,
                                  WEIGHTS)
from clnn_ros.graph.task_description import Described, description_problem

TYPES = {CLOCK: Clock, TRIAL_EVENT: TrialEvent, STATE: Observation, SPIKES: SpikeVector,
         REWARD: Reward, ACTION: Action, WEIGHTS: WeightSnapshot, TASK: TaskDescription}
TICKED = (CLOCK, TRIAL_EVENT, STATE, SPIKES, REWARD, ACTION, WEIGHTS)  # refused by tick or content
WELL_FORMED = ("stale_tick", "far_tick", "foreign_graph")
MALFORMED = {CLOCK: ("between_ticks", "nanosec_overflow"),
             TRIAL_EVENT: ("unknown_kind", "non_finite_angle", "angle_out_of_range"),
             STATE: ("non_finite", "too_many_steps", "reason_not_terminated"),
             SPIKES: ("wrong_size", "not_one_hot"),
             REWARD: ("both_lines", "not_binary"),
             ACTION: ("no_such_action", "no_such_segment", "none_with_segment"),
             WEIGHTS: ("wrong_size", "non_finite", "out_of_range"),
             TASK: ("other_version", "unpaired_lists", "bad_bounds", "not_the_runs_task")}
# env/task's fuzz that is a description of the run's own task (taken, were it the first)
TASK_COPY = "the_runs_own"
IGNORED = "ignored"  # what env/task's subscribers do with its fuzz (judged)
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
        self.task = Described(cartpole_task(p), CARTPOLE_TERMINATIONS)  # the run's, described
        self.foreign_trial0 = rng.randint(0, 10_000)

    def make(self, topic: str, category: str, live: int):
        if topic == TASK:
            return self._TaskDescription(category)
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

    def _Observation(self, _tick: int, category: str) -> Observation:
        """The cart-pole's observation (its variables' order, its bounds): a well-formed one
        fits the run's task (the encoder checks it), a malformed one breaks a content rule."""
        rng, p = self.rng, self.p
        values = [rng.uniform(-0.9, 0.9) * p.track_limit_m, rng.uniform(-3, 3),
                  rng.uniform(-0.9, 0.9) * p.angle_limit_deg, rng.uniform(-100, 100)]
        msg = Observation(reward=rng.choice([0.0, 1.0]), truncated=rng.random() < 0.05,
                          successful_steps=rng.randint(0, p.max_steps))
        if category in WELL_FORMED and rng.random() < 0.2:  # a trial's terminating observation
            msg.terminated, msg.truncated = True, False
            msg.termination = rng.randint(1, len(CARTPOLE_TERMINATIONS))
            if CARTPOLE_TERMINATIONS[msg.termination - 1] == "pole_angle":
                values[2] = rng.choice([-1, 1]) * rng.uniform(p.angle_limit_deg, 30)
            else:
                values[0] = rng.choice([-1, 1]) * rng.uniform(p.track_limit_m, 3)
        elif category == "non_finite":
            if rng.random() < 0.8:
                values[rng.randrange(len(values))] = rng.choice(NON_FINITE)
            else:
                msg.reward = rng.choice(NON_FINITE)
        elif category == "too_many_steps":
            msg.successful_steps = p.max_steps + rng.randint(1, 1000)
        elif category == "reason_not_terminated":
            msg.termination = rng.randint(1, 255)
        msg.values = values
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
        # well-formed: an action, or ACTION_NONE (the answer to a trial's last observation)
        if category in WELL_FORMED and rng.random() < 0.2:
            return Action(action=ACTION_NONE, winning_segment=0)
        msg = Action(action=rng.randrange(p.n_actions),
                     winning_segment=rng.randrange(p.n_segments))
        if category == "no_such_action":
            msg.action = rng.randint(p.n_actions, ACTION_NONE - 1)
        elif category == "no_such_segment":
            msg.winning_segment = rng.randint(p.n_segments, 255)
        elif category == "none_with_segment":
            msg.action, msg.winning_segment = ACTION_NONE, rng.randint(1, 255)
        return msg

    def _WeightSnapshot(self, _tick: int, category: str) -> WeightSnapshot:
        rng, p = self.rng, self.p
        shape = [p.n_actions, p.n_segments, p.n_inputs]
        if category == "wrong_size":
            shape[rng.randrange(3)] += rng.choice([-1, 1])
        weights = [rng.uniform(0, p.w_max) for _ in range(math.prod(shape))]
        if category == "wrong_size" and rng.random() < 0.5:  # the right shape, a wrong length
            shape = [p.n_actions, p.n_segments, p.n_inputs]
        if category == "non_finite":
            weights[rng.randrange(len(weights))] = rng.choice(NON_FINITE)
        elif category == "out_of_range":
            weights[rng.randrange(len(weights))] = rng.choice([-rng.uniform(1e-6, 10),
                                                               p.w_max + rng.uniform(1e-6, 10)])
        return WeightSnapshot(neurons=shape[0], segments=shape[1], inputs=shape[2],
                              weights=weights)


    def _TaskDescription(self, category: str) -> TaskDescription:
        """The run's own task (the cart-pole with its limits), as its environment describes it,
        or one broken as `category` says."""
        rng = self.rng
        fields = self.task.fields()
        if category == "other_version":
            fields["contract_version"] = rng.choice([0, 1, 2, 3, 5, 65535])
        elif category == "unpaired_lists":
            key = rng.choice(["variable_names", "variable_units", "variable_low",
                              "variable_high", "action_labels", "action_values"])
            fields[key] = fields[key][:-1] if rng.random() < 0.5 else \
                fields[key] + fields[key][:1]
        elif category == "bad_bounds":
            which = rng.randrange(len(fields["variable_low"]))
            if rng.random() < 0.5:
                fields["variable_low" if rng.random() < 0.5 else "variable_high"][which] = \
                    math.nan
            else:
                fields["variable_low"][which], fields["variable_high"][which] = 1.0, -1.0
        elif category == "not_the_runs_task":
            which = rng.randrange(3)
            if which == 0:  # a third action: not the run's two neurons
                fields["action_labels"] = fields["action_labels"] + ["none"]
                fields["action_values"] = fields["action_values"] + [0.0]
            elif which == 1:  # another task's name
                fields["task"] = rng.choice(["gymnasium:CartPole-v1", "robot", ""])
            else:  # no pole angle, the variable the run encodes
                for key in ("variable_names", "variable_units", "variable_low",
                            "variable_high"):
                    del fields[key][2]
        return TaskDescription(**fields)


def schedule(per_topic: int, rng: random.Random) -> dict[str, list[str]]:
    """For every topic, the categories of its messages: all of them equally often, shuffled
    (env/task's: its malformed ones and the run's own)."""
    plan = {}
    for topic in TYPES:
        categories = (*MALFORMED[topic], TASK_COPY) if topic == TASK else \
            (*MALFORMED[topic], *WELL_FORMED)
        plan[topic] = [categories[i % len(categories)] for i in range(per_topic)]
        rng.shuffle(plan[topic])
    return plan


def clock_tick(msg: Clock, tau_ns: int) -> int:
    return stamp_nanoseconds(msg.clock.sec, msg.clock.nanosec) // tau_ns


def judged(topic: str, category: str, received, live: int,
           maker: MessageMaker) -> tuple[str | None, int | None]:
    """(what every subscriber of `topic` does with a fuzz message as it receives it: "content"
    or "tick", the kind of its refusal, IGNORED for env/task's; None where the message is not
    of its category, a fuzzer bug) and its tick (None for env/task's)."""
    if topic == TASK:
        fits = description_problem(received, maker.p) is None
        return (IGNORED if fits == (category == TASK_COPY) else None), None
    malformed = RULES[topic](received, maker.p) is not None
    tick = clock_tick(received, maker.tau_ns) if topic == CLOCK else received.tick
    if category == "stale_tick":
        in_category = not malformed and 0 <= tick <= live - STALE
    elif category in WELL_FORMED:
        in_category = not malformed and live + FAR <= tick <= maker.max_tick
    else:
        in_category = malformed
    if topic == TRIAL_EVENT and category in WELL_FORMED:
        in_category &= received.event == TrialEvent.EPISODE_END
    if topic == STATE and not malformed:  # the encoder checks it against the task too
        in_category &= maker.task.observation_problem(received.values) is None
    return ("content" if malformed else "tick") if in_category else None, tick
