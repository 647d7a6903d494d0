"""Fuzzer for the running ROS graph: publishes malformed and hostile messages on every input
topic of the graph while an episode runs, and reports what it sent.

    python scripts/fuzz_graph.py [--seed 0] [--per-topic 1000] [--per-tick 3] [--nsv 1]
                                 [--max-steps 10000] [--report fuzz.json]

Start it beside `python -m clnn_ros.run_all ...` on the same ROS_DOMAIN_ID, with the run's
--nsv and --max-steps (it builds messages for that network). Start it first: it waits for the
graph (a participant that joins a running graph is discovered late). Once its publishers have
matched the graph's subscribers, it sends, on each real /clock(t) (one it did not send itself),
--per-tick messages on each input topic aimed at the live tick t, until each topic has had
--per-topic messages. Every message is of one category:

  malformed (refused by every subscriber for its content, docs/ROS_GRAPH.md): per topic, e.g.
    non-finite or out-of-range or inconsistent states, wrong-sized spike vectors or weights,
    out-of-range actions, unknown event kinds, clocks between two ticks;
  well-formed, refused because the fuzzer is not the topic's publisher:
    wrong_tick (far from t), duplicate_tick (t again), reordered_tick (t-3..t+3),
    hostile_next_tick (exactly the tick the real message of the topic comes with next, so it
    races the real one, e.g. an EPISODE_END or the state of tick t).

Categories are drawn evenly per topic and shuffled with --seed (the counts are deterministic;
the ticks follow the live graph). Exit 0 with the report (JSON, to --report or stdout): per
topic the messages sent per category and the refusals to expect from each of its subscribers
("content" or "publisher"), and the subscribers. Exit 1 with one line if the graph does not
start, the episode ends before everything was sent, or a message was not delivered. Each
message is judged as the nodes will see it (after a serialization round trip) and must fall in
its category, or the fuzzer stops (a fuzzer bug).
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
from clnn_ros.nodes.common import (ACTION, CLOCK, CONTENT_RULES, LOCKSTEP_QOS, REWARD, SPIKES,
                                   STATE, TRIAL_EVENT, WEIGHTS, make_executor, ros_session)
from clnn_ros.nodes.publisher_gid import InputsWithGid
from clnn_ros.nodes.validate import N_NEURONS

NODE_NAME = "fuzz_graph"
STARTUP_TIMEOUT_S = 60.0
ACK_TIMEOUT_S = 10.0
TYPES = {CLOCK: Clock, TRIAL_EVENT: TrialEvent, STATE: CartPoleState, SPIKES: SpikeVector,
         REWARD: Reward, ACTION: Action, WEIGHTS: WeightSnapshot}
# The nodes of the graph that subscribe to each input topic (docs/ROS_GRAPH.md).
SUBSCRIBERS = {CLOCK: ["environment"], TRIAL_EVENT: ["environment", "encoder", "reward", "agent"],
               STATE: ["encoder", "reward", "trial_manager"], SPIKES: ["agent", "trial_manager"],
               REWARD: ["agent", "trial_manager"], ACTION: ["environment", "trial_manager"],
               WEIGHTS: ["trial_manager"]}
WELL_FORMED = ("wrong_tick", "duplicate_tick", "reordered_tick", "hostile_next_tick")
MALFORMED = {CLOCK: ("between_ticks", "nanosec_overflow"),
             TRIAL_EVENT: ("unknown_kind", "non_finite_angle", "angle_out_of_range"),
             STATE: ("non_finite", "out_of_range", "inconsistent"),
             SPIKES: ("wrong_size", "not_one_hot"),
             REWARD: ("unknown_kind", "inconsistent_code"),
             ACTION: ("out_of_range", "non_finite_force", "inconsistent_force", "no_such_neuron"),
             WEIGHTS: ("wrong_size", "non_finite", "out_of_range")}
NON_FINITE = (math.nan, math.inf, -math.inf)
INT32_MAX = 2**31 - 1  # builtin_interfaces/Time.sec: a stamp's seconds


class MessageMaker:
    """Builds the fuzz messages of one network (Params) from one random stream."""

    def __init__(self, p: Params, rng: random.Random):
        self.p, self.rng = p, rng
        self.tau_ns = round(p.tau * 1e9)
        self.max_tick = INT32_MAX * 10**9 // self.tau_ns  # the last tick a stamp can carry
        self.n_angle_inputs = len(p.angle_edges_deg) + 1

    def make(self, topic: str, category: str, live: int):
        tick = self.tick(topic, category, live)
        msg = getattr(self, "_" + TYPES[topic].__name__)(tick, category)
        if topic != CLOCK:
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(tick * self.tau_ns, 10**9)
            msg.tick, msg.trial = tick, self.rng.randint(0, 50)
        return msg

    def tick(self, topic: str, category: str, live: int) -> int:
        """The tick a message of `category` carries, near the live tick `live` (the last real
        /clock): the real messages of tick live are under way, /clock(live + 1) comes next."""
        rng = self.rng
        if category == "wrong_tick":
            return rng.choice([rng.randint(live + 10, self.max_tick),
                               rng.randint(0, max(0, live - 10))])
        if category == "reordered_tick":
            return max(0, live + rng.choice([-3, -2, -1, 1, 2, 3]))
        if category == "hostile_next_tick" and topic in (CLOCK, TRIAL_EVENT):
            return live + 1
        return live  # duplicate_tick, hostile_next_tick, and the malformed ones

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
        msg = TrialEvent(event=rng.choice([TrialEvent.START, TrialEvent.END,
                                           TrialEvent.EPISODE_END]),
                         initial_angle_deg=rng.uniform(-0.9, 0.9) * limit,
                         successful_steps=rng.randint(0, self.p.max_steps),
                         seed=rng.randint(0, 99))
        if category == "unknown_kind":
            msg.event = rng.randint(3, 255)
        elif category in ("non_finite_angle", "angle_out_of_range"):
            msg.event = TrialEvent.START
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
        if category == "non_finite":
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
        direction = rng.choice([-1, 1])
        msg = Action(force_direction=direction, force_n=direction * p.force,
                     winning_neuron=int(direction > 0),
                     winning_segment=rng.randrange(p.n_segments))
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


class Fuzzer(Node):
    def __init__(self, p: Params, seed: int, per_topic: int, per_tick: int):
        super().__init__(NODE_NAME)
        self.p, self.per_tick = p, per_tick
        rng = random.Random(seed)
        self.plan = schedule(per_topic, rng)
        self.maker = MessageMaker(p, rng)
        self.sent = {topic: Counter() for topic in TYPES}
        self.refusals = {topic: Counter() for topic in TYPES}
        self.fuzz_publishers = {topic: self.create_publisher(TYPES[topic], topic, LOCKSTEP_QOS)
                                for topic in TYPES}
        self.episode_ended = False
        self.graph_started = False
        self.own_gids = {}  # topic: GIDs of this fuzzer's publishers of /clock, /trial/event
        self.inputs = InputsWithGid(self)
        self.inputs.subscribe(Clock, CLOCK, self.on_clock, LOCKSTEP_QOS)
        self.inputs.subscribe(TrialEvent, TRIAL_EVENT, self.on_event, LOCKSTEP_QOS)

    def armed(self) -> bool:
        """Has every fuzz publisher matched the graph's subscribers of its topic?"""
        return all(self.fuzz_publishers[topic].get_subscription_count() >= len(nodes)
                   for topic, nodes in SUBSCRIBERS.items())

    def from_graph(self, topic: str, publisher_gid: bytes) -> bool:
        """Did anyone but this fuzzer, i.e. the graph, send it? (The ROS graph may name a remote
        publisher's node only seconds after its first message; ours it knows at once.)"""
        if topic not in self.own_gids:
            self.own_gids[topic] = {bytes(info.endpoint_gid)
                                    for info in self.get_publishers_info_by_topic(topic)
                                    if info.node_name == self.get_name()}
        return publisher_gid not in self.own_gids[topic]

    def on_event(self, msg_and_sender: tuple) -> None:
        msg, publisher_gid = msg_and_sender
        if msg.event == TrialEvent.EPISODE_END and self.from_graph(TRIAL_EVENT, publisher_gid):
            self.episode_ended = True

    def on_clock(self, msg_and_sender: tuple) -> None:
        msg, publisher_gid = msg_and_sender
        if not self.from_graph(CLOCK, publisher_gid):
            return
        self.graph_started = True
        if not self.armed():
            return
        live = (msg.clock.sec * 10**9 + msg.clock.nanosec) // self.maker.tau_ns
        for topic, plan in self.plan.items():
            for category in plan[:self.per_tick]:
                self.send(topic, category, live)
            del plan[:self.per_tick]

    def send(self, topic: str, category: str, live: int) -> None:
        msg = self.maker.make(topic, category, live)
        received = deserialize_message(serialize_message(msg), TYPES[topic])  # what nodes see
        malformed = CONTENT_RULES[topic](received, self.p) is not None
        if malformed != (category in MALFORMED[topic]):
            raise AssertionError(f"fuzzer bug: {topic} {category} message {msg} is "
                                 f"{'malformed' if malformed else 'well-formed'}")
        self.fuzz_publishers[topic].publish(msg)
        self.sent[topic][category] += 1
        self.refusals[topic]["content" if malformed else "publisher"] += 1

    def done(self) -> bool:
        return not any(self.plan.values())

    def report(self, seed: int) -> dict:
        return {"seed": seed, "sent": {t: dict(c) for t, c in self.sent.items()},
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
    parser.add_argument("--report", help="write the JSON report here (default: stdout)")
    args = parser.parse_args(argv)
    if args.per_topic < 1 or args.per_tick < 1:
        parser.error("--per-topic and --per-tick must be positive")
    try:
        p = Params(nsv=args.nsv, max_steps=args.max_steps)
    except ParamError as error:
        parser.error(str(error))
    with ros_session() as signals:
        fuzzer = Fuzzer(p, args.seed, args.per_topic, args.per_tick)
        executor = make_executor()
        executor.add_node(fuzzer)
        try:
            deadline = time.monotonic() + STARTUP_TIMEOUT_S
            while not fuzzer.done() and not fuzzer.episode_ended and not signals:
                executor.spin_once(timeout_sec=0.1)
                if not fuzzer.graph_started and time.monotonic() > deadline:
                    print(f"fuzz_graph: error: no /clock from the graph within "
                          f"{STARTUP_TIMEOUT_S:.0f} s", file=sys.stderr)
                    return 1
            if signals:
                return 128 + signals[0]
            if not fuzzer.done():
                left = sum(map(len, fuzzer.plan.values()))
                print(f"fuzz_graph: error: the episode ended before the fuzz was sent "
                      f"({left} messages left)", file=sys.stderr)
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
            fuzzer.inputs.close()
            fuzzer.destroy_node()


if __name__ == "__main__":
    sys.exit(main())
