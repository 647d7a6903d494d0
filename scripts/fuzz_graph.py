"""Fuzzer for the running ROS graph: publishes malformed and hostile messages on every input
topic of the graph while an episode runs, and reports what it sent.

    python scripts/fuzz_graph.py [--seed 0] [--per-topic 1000] [--per-tick 3] [--nsv 1]
                                 [--max-steps 10000] [--namespace /] [--report fuzz.json]

Start it beside `python -m clnn_ros.run_all ...` on the same ROS_DOMAIN_ID and namespace, with
the run's --nsv and --max-steps (it builds messages for that network). Start it first: it waits
for the graph (a participant that joins a running graph is discovered late). Once its
publishers have matched the graph's subscribers, it sends, on each clock(t) of the graph it
sees, --per-tick messages on each input topic, until each topic has had --per-topic messages.

Like the nodes, it uses public rclpy only and never asks who sent a message: it tells the
graph's clock from its own by content (its own clocks are malformed, or of ticks it remembers
sending, and the graph's clock only moves forward), and the graph's EPISODE_END likewise.

Every message is of one category, and every subscriber of its topic refuses it
(GraphNode.refusal_summary counts the refusals by topic and kind):

  malformed, refused for its content (kind "content", validate.py), whatever its tick (t):
    non-finite or out-of-range or inconsistent states, wrong-sized or not 1-hot spike vectors,
    unknown or inconsistent rewards, out-of-range or inconsistent actions, wrong-sized or
    out-of-range weights, unknown event kinds or STARTs outside the angle limit, clocks between
    two ticks or with nanosec >= 1e9;
  well-formed, refused for its tick (kind "tick"):
    stale_tick     a tick 0..t-STALE (sent only from t >= STALE_FROM), behind every
                   subscriber: the trial manager published clock(t) only once every node had
                   finished tick t-1. What a node takes late comes within a tick or two, far
                   less than STALE: the environment holds a trial's force-0 action of tick L
                   before it publishes state(L+2) (one writer's actions come in order), the
                   trial manager's spikes and rewards trail its actions, and its weights of L
                   follow action(L);
    far_tick       a tick t+FAR..the last one a header stamp can carry (sec is int32), that an
                   episode never reaches (512 trials of 10,000 steps are 5.1 M ticks);
    foreign_graph  the messages another graph on the same domain and namespace would send: an
                   episode at a phase of FAR..2*FAR ticks ahead of this one (one phase per run),
                   its ticks t + phase moving with the live tick, its trials counted along.
  On trial/event the well-formed messages are EPISODE_ENDs: every node checks the tick of an
  EPISODE_END (GraphNode.on_trial_event: the node's current tick or the one before), only the
  environment acts on START (at the tick after a trial end, checked there) and no node on END,
  so a well-formed START or END of another tick is not refused by every subscriber.

Not fuzzed: a well-formed message with the tick the real one carries or next to it (a
duplicate, a reordered one, one that races the real message of the tick, such as a forged
EPISODE_END of the current tick). Without sender authentication a node cannot tell it from the
real one, and whichever comes first is taken. The remedy is outside the nodes: a ROS domain id
and a namespace of the graph's own, DDS discovery on the loopback only
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, clnn_ros's default), and on a full ROS install SROS2
access control (signed permissions: only the trial manager may publish the clock and the trial
events, only the environment the state, ...).

Categories are drawn evenly per topic and shuffled with --seed (the counts are deterministic;
the ticks follow the live graph). Exit 0 with the report (JSON, to --report or stdout): per
topic the messages sent per category, the subscribers that refuse them (the graph nodes that
subscribe; the sim-time clock of every node but the trial manager also hears /clock and refuses
nothing), and the refusals to expect from each of those subscribers by kind ("content",
"tick"). Exit 1 with one line if the graph does not start, the episode ends before everything
was sent, or a message was not delivered. Each message is judged as the nodes will see it
(after a serialization round trip) and must fall in its category, or the fuzzer stops (a fuzzer
bug).
"""

from __future__ import annotations

import argparse
import json
import math
import random
import sys
import time
from collections import Counter

from clnn_ros import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy)

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from clnn_ros_msgs.msg import (Action, CartPoleState, Reward, SpikeVector, TrialEvent,
                               WeightSnapshot)
from rosgraph_msgs.msg import Clock

from clnn_ros.core.params import ParamError, Params
from clnn_ros.core.rln import ONE_HOT, REWARD_KINDS
from clnn_ros.names import (ACTION, CLOCK, GRAPH_NODES, REWARD, SPIKES, STATE, TRIAL_EVENT,
                            TRIAL_MANAGER, WEIGHTS)
from clnn_ros.nodes.common import CONTENT_RULES, LOCKSTEP_QOS, make_executor, ros_session
from clnn_ros.nodes.validate import FAILURE_REASONS, N_NEURONS

NODE_NAME = "fuzz_graph"
STARTUP_TIMEOUT_S = 60.0
ACK_TIMEOUT_S = 10.0
TYPES = {CLOCK: Clock, TRIAL_EVENT: TrialEvent, STATE: CartPoleState, SPIKES: SpikeVector,
         REWARD: Reward, ACTION: Action, WEIGHTS: WeightSnapshot}
# The nodes of the graph that subscribe to each input topic (docs/ROS_GRAPH.md).
SUBSCRIBERS = {CLOCK: ["environment"], TRIAL_EVENT: ["environment", "encoder", "reward", "agent"],
               STATE: ["encoder", "reward", TRIAL_MANAGER], SPIKES: ["agent", TRIAL_MANAGER],
               REWARD: ["agent", TRIAL_MANAGER], ACTION: ["environment", TRIAL_MANAGER],
               WEIGHTS: [TRIAL_MANAGER]}
# Who else hears a topic: the sim-time clock (use_sim_time) of every node but the trial manager
# subscribes to /clock; the fuzzer itself listens to clock and trial/event.
OTHER_SUBSCRIPTIONS = {CLOCK: len(GRAPH_NODES) + 1, TRIAL_EVENT: 1}
WELL_FORMED = ("stale_tick", "far_tick", "foreign_graph")
MALFORMED = {CLOCK: ("between_ticks", "nanosec_overflow"),
             TRIAL_EVENT: ("unknown_kind", "non_finite_angle", "angle_out_of_range"),
             STATE: ("non_finite", "out_of_range", "inconsistent"),
             SPIKES: ("wrong_size", "not_one_hot"),
             REWARD: ("unknown_kind", "inconsistent_code"),
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
        self.tau_ns = round(p.tau * 1e9)
        self.max_tick = INT32_MAX * 10**9 // self.tau_ns  # the last tick a stamp can carry
        self.n_angle_inputs = len(p.angle_edges_deg) + 1
        self.foreign_phase = rng.randint(FAR, 2 * FAR)  # the other graph's lead, in ticks
        self.foreign_trial0 = rng.randint(0, 10_000)

    def make(self, topic: str, category: str, live: int):
        tick = self.tick(category, live)
        msg = getattr(self, "_" + TYPES[topic].__name__)(tick, category)
        if topic != CLOCK:
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(tick * self.tau_ns, 10**9)
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
        msg.clock.sec, msg.clock.nanosec = divmod(nanoseconds, 10**9)
        if category == "nanosec_overflow":
            msg.clock.nanosec = self.rng.randint(10**9, 2**32 - 1)
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
            msg.failed, msg.failure_reason = True, rng.choice(FAILURE_REASONS)
            if msg.failure_reason == CartPoleState.FAILURE_POLE_ANGLE:
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
        elif category == "inconsistent":
            msg.failed, msg.failure_reason = rng.choice(
                [(True, ""), (False, CartPoleState.FAILURE_POLE_ANGLE), (True, "gremlins")])
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
        return SpikeVector(spikes=spikes, spiking_inputs=[i for i, s in enumerate(spikes) if s])

    def _Reward(self, _tick: int, category: str) -> Reward:
        rng = self.rng
        kind = rng.randrange(len(REWARD_KINDS))
        msg = Reward(kind=REWARD_KINDS[kind], reward_one_hot=ONE_HOT[kind],
                     success_counter=rng.randint(0, 255), trial_over=rng.random() < 0.1)
        if category == "unknown_kind":
            msg.kind = rng.choice(["jackpot", "", "REWARD", "punish ", "None"])
        elif category == "inconsistent_code":
            msg.reward_one_hot = rng.choice([c for c in (*ONE_HOT.values(), (1, 1))
                                             if c != ONE_HOT[kind]])
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
    return (msg.clock.sec * 10**9 + msg.clock.nanosec) // tau_ns


class Fuzzer(Node):
    def __init__(self, p: Params, seed: int, per_topic: int, per_tick: int,
                 namespace: str = "/"):
        super().__init__(NODE_NAME, namespace=namespace)
        self.p, self.per_tick = p, per_tick
        rng = random.Random(seed)
        self.plan = schedule(per_topic, rng)
        self.maker = MessageMaker(p, rng)
        self.sent = {topic: Counter() for topic in TYPES}
        self.refusals = {topic: Counter() for topic in TYPES}
        self.fuzz_publishers = {topic: self.create_publisher(TYPES[topic], topic, LOCKSTEP_QOS)
                                for topic in TYPES}
        self.episode_ended = False
        self.live = None  # the tick of the last clock of the graph seen
        self.fuzzed_ticks = []  # the first and the last live tick it sent messages on
        # The ticks of the well-formed clocks and EPISODE_ENDs this fuzzer sent: it hears them
        # too, and tells the graph's by content alone.
        self.own_ticks = {CLOCK: set(), TRIAL_EVENT: set()}
        self.create_subscription(Clock, CLOCK, self.on_clock, LOCKSTEP_QOS)
        self.create_subscription(TrialEvent, TRIAL_EVENT, self.on_event, LOCKSTEP_QOS)

    def armed(self) -> bool:
        """Has every fuzz publisher matched every subscription of its topic: the graph's
        subscribers, the nodes' sim-time clocks and the fuzzer's own?"""
        return all(self.fuzz_publishers[topic].get_subscription_count() >=
                   len(nodes) + OTHER_SUBSCRIPTIONS.get(topic, 0)
                   for topic, nodes in SUBSCRIBERS.items())

    def on_event(self, msg: TrialEvent) -> None:
        if msg.event == TrialEvent.EPISODE_END and \
                CONTENT_RULES[TRIAL_EVENT](msg, self.p) is None and \
                msg.tick not in self.own_ticks[TRIAL_EVENT]:
            self.episode_ended = True

    def on_clock(self, msg: Clock) -> None:
        """A clock of the graph: well-formed, of a tick this fuzzer did not send, ahead of the
        last one (its stale clocks are behind it, its far and foreign ones it remembers)."""
        if CONTENT_RULES[CLOCK](msg, self.p) is not None:
            return
        tick = clock_tick(msg, self.maker.tau_ns)
        if tick in self.own_ticks[CLOCK] or (self.live is not None and tick <= self.live):
            return
        self.live = tick
        if self.armed() and not self.done():
            self.fuzz(tick)
            self.fuzzed_ticks = [(self.fuzzed_ticks or [tick])[0], tick]

    def fuzz(self, live: int) -> None:
        """Up to --per-tick messages on each topic, in the order of the plan (stale ones wait
        for live >= STALE_FROM)."""
        for topic, plan in self.plan.items():
            chosen = []
            for i, category in enumerate(plan):
                if len(chosen) == self.per_tick:
                    break
                if category != "stale_tick" or live >= STALE_FROM:
                    chosen.append(i)
            for i in chosen:
                self.send(topic, plan[i], live)
            for i in reversed(chosen):
                del plan[i]

    def send(self, topic: str, category: str, live: int) -> None:
        msg = self.maker.make(topic, category, live)
        received = deserialize_message(serialize_message(msg), TYPES[topic])  # what nodes see
        malformed = CONTENT_RULES[topic](received, self.p) is not None
        tick = clock_tick(received, self.maker.tau_ns) if topic == CLOCK else received.tick
        if category == "stale_tick":
            in_category = not malformed and 0 <= tick <= live - STALE
        elif category in WELL_FORMED:
            in_category = not malformed and live + FAR <= tick <= self.maker.max_tick
        else:
            in_category = malformed
        if topic == TRIAL_EVENT and category in WELL_FORMED:
            in_category &= received.event == TrialEvent.EPISODE_END
        if not in_category:
            raise AssertionError(f"fuzzer bug: {topic} {category} message {received} at live "
                                 f"tick {live} is not of its category")
        if not malformed and topic in self.own_ticks:
            self.own_ticks[topic].add(tick)
        self.fuzz_publishers[topic].publish(msg)
        self.sent[topic][category] += 1
        self.refusals[topic]["content" if malformed else "tick"] += 1

    def done(self) -> bool:
        return not any(self.plan.values())

    def report(self, seed: int) -> dict:
        return {"seed": seed, "foreign_phase": self.maker.foreign_phase,
                "fuzzed_ticks": self.fuzzed_ticks,
                "sent": {t: dict(c) for t, c in self.sent.items()},
                "refusals_per_subscriber": {t: dict(c) for t, c in self.refusals.items()},
                "subscribers": SUBSCRIBERS}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=0, help="random stream of the fuzz")
    parser.add_argument("--per-topic", type=int, default=1000, help="messages per input topic")
    parser.add_argument("--per-tick", type=int, default=3,
                        help="messages per topic on each tick of the graph")
    parser.add_argument("--nsv", type=int, default=1, help="the run's --nsv")
    parser.add_argument("--max-steps", type=int, default=10_000, help="the run's --max-steps")
    parser.add_argument("--namespace", default="/", help="the run's --namespace")
    parser.add_argument("--report", help="write the JSON report here (default: stdout)")
    args = parser.parse_args(argv)
    if args.per_topic < 1 or args.per_tick < 1:
        parser.error("--per-topic and --per-tick must be positive")
    try:
        p = Params(nsv=args.nsv, max_steps=args.max_steps)
    except ParamError as error:
        parser.error(str(error))
    namespace = "/" + args.namespace.strip("/")
    with ros_session() as signals:
        fuzzer = Fuzzer(p, args.seed, args.per_topic, args.per_tick, namespace)
        executor = make_executor()
        executor.add_node(fuzzer)
        try:
            deadline = time.monotonic() + STARTUP_TIMEOUT_S
            while not fuzzer.done() and not fuzzer.episode_ended and not signals:
                executor.spin_once(timeout_sec=0.1)
                if fuzzer.live is None and time.monotonic() > deadline:
                    print(f"fuzz_graph: error: no clock from the graph within "
                          f"{STARTUP_TIMEOUT_S:.0f} s", file=sys.stderr)
                    return 1
            if signals:
                return 128 + signals[0]
            if not fuzzer.done():
                left = sum(map(len, fuzzer.plan.values()))
                print(f"fuzz_graph: error: the episode ended before the fuzz was sent "
                      f"({left} messages left; sent on the graph's ticks "
                      f"{fuzzer.fuzzed_ticks or 'none'}, the last tick seen {fuzzer.live})",
                      file=sys.stderr)
                return 1
            if not all(publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))
                       for publisher in fuzzer.fuzz_publishers.values()):
                print(f"fuzz_graph: error: not every message was delivered within "
                      f"{ACK_TIMEOUT_S:.0f} s", file=sys.stderr)
                return 1
            text = json.dumps(fuzzer.report(args.seed), indent=1)
            if args.report:
                with open(args.report, "w") as f:
                    f.write(text)
            else:
                print(text)
            return 0
        finally:
            fuzzer.destroy_node()


if __name__ == "__main__":
    sys.exit(main())
