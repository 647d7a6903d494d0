"""Fuzzer for the running ROS graph: publishes malformed and hostile messages on every input
topic of the graph while an episode runs, and reports what it sent.

    python scripts/fuzz_graph.py [--seed 0] [--per-topic 1000] [--per-tick 3] [--nsv 1]
                                 [--max-steps 10000] [--namespace /] [--report fuzz.json]

Start it beside `python -m clnn_ros.run_all ...` on the same ROS_DOMAIN_ID and namespace, with
the run's --nsv and --max-steps (it builds messages for that network). Start it first: it waits
for the graph (a participant that joins a running graph is discovered late). Once its
publishers have matched the graph's subscribers, it sends, on each clock(t) of the graph it
sees, --per-tick messages on each input topic, until each topic has had --per-topic messages;
then it stays until the episode ends (GRAPH_SILENT_S).

Like the nodes, it uses public rclpy only and never asks who sent a message: it tells the
graph's clock from its own by content (its own clocks are malformed, or of ticks it remembers
sending, and the graph's clock only moves forward), and the graph's EPISODE_END likewise.

Every message is of one category (scripts/fuzz_messages.py: malformed, refused for its content;
well-formed but of a tick no node is at, refused for its tick), and every subscriber of its
topic refuses it; but env/task's (TaskDescriptions, latched, without a tick), which every
subscriber ignores once it holds the run's task, before the first tick.

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
"tick"; none on env/task: "ignored" counts what they ignore). Exit 1 with one line if the graph does not start, the episode ends before everything
was sent, or a message was not delivered. Each message is judged as the nodes will see it
(after a serialization round trip) and must fall in its category, or the fuzzer stops (a fuzzer
bug).
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import random
import sys
import time
from collections import Counter

from clnn_ros.session import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy)

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from clnn_ros_msgs.msg import TrialEvent
from rosgraph_msgs.msg import Clock

from clnn_ros.core.params import ParamError, Params
from clnn_ros.graph import qos
from clnn_ros.graph.content import RULES
from clnn_ros.graph.names import (ACTION, CLOCK, REWARD, SIM_TIME_NODES, SPIKES, STATE, TASK,
                                  TRIAL_EVENT, TRIAL_MANAGER, WEIGHTS)
from clnn_ros.session.rclpy_session import make_executor, qos_profile, ros_session
from fuzz_messages import (IGNORED, STALE_FROM, TYPES, MessageMaker, clock_tick, judged,
                           schedule)

NODE_NAME = "fuzz_graph"
STARTUP_TIMEOUT_S = 60.0
EXIT_HANG_S = 60.0
ACK_TIMEOUT_S = 10.0
# After the fuzz it stays until the episode ends (the graph silent this long: gone), so that the
# trial manager names it: it looks at the ROS graph every 0.5 s and names a publisher only once
# its node's name has come (rmw sends a participant's node names apart from its endpoints; a
# fuzzer that left at once, 30 ms after its first message composed, was never named).
GRAPH_SILENT_S = 30.0
LOCKSTEP_QOS = qos_profile(qos.LOCKSTEP)
LATCHED_QOS = qos_profile(qos.LABELS)  # env/task's: its subscribers ask for a latched topic
# The nodes of the graph that subscribe to each input topic (docs/ROS_GRAPH.md).
SUBSCRIBERS = {CLOCK: ["environment"], TRIAL_EVENT: ["environment", "encoder", "reward", "agent"],
               STATE: ["encoder", "reward", TRIAL_MANAGER], SPIKES: ["agent", TRIAL_MANAGER],
               REWARD: ["agent", TRIAL_MANAGER], ACTION: ["environment", TRIAL_MANAGER],
               WEIGHTS: [TRIAL_MANAGER], TASK: ["encoder", TRIAL_MANAGER]}
# Who else hears a topic: the sim-time clock (use_sim_time) of SIM_TIME_NODES subscribes to
# /clock; the fuzzer itself listens to clock and trial/event.
OTHER_SUBSCRIPTIONS = {CLOCK: len(SIM_TIME_NODES) + 1, TRIAL_EVENT: 1}
# What every subscriber of a topic refuses for its content (docs/ROS_GRAPH.md, "What a node
# refuses").
REFUSED = RULES


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
        self.ignored = Counter()  # env/task's fuzz, by category
        self.fuzz_publishers = {topic: self.create_publisher(
            TYPES[topic], topic, LATCHED_QOS if topic == TASK else LOCKSTEP_QOS)
            for topic in TYPES}
        self.episode_ended = False
        self.live = self.live_at = None  # the tick of the last clock of the graph seen; when
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
                REFUSED[TRIAL_EVENT](msg, self.p) is None and \
                msg.tick not in self.own_ticks[TRIAL_EVENT]:
            self.episode_ended = True

    def on_clock(self, msg: Clock) -> None:
        """A clock of the graph: well-formed, of a tick this fuzzer did not send, ahead of the
        last one (its stale clocks are behind it, its far and foreign ones it remembers)."""
        if REFUSED[CLOCK](msg, self.p) is not None:
            return
        tick = clock_tick(msg, self.maker.tau_ns)
        if tick in self.own_ticks[CLOCK] or (self.live is not None and tick <= self.live):
            return
        self.live, self.live_at = tick, time.monotonic()
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
        kind, tick = judged(topic, category, received, live, self.maker)
        if kind is None:
            raise AssertionError(f"fuzzer bug: {topic} {category} message {received} at live "
                                 f"tick {live} is not of its category")
        if kind == "tick" and topic in self.own_ticks:
            self.own_ticks[topic].add(tick)
        self.fuzz_publishers[topic].publish(msg)
        self.sent[topic][category] += 1
        if kind == IGNORED:  # env/task's: its subscribers took the run's task before the start
            self.ignored[category] += 1
        else:
            self.refusals[topic][kind] += 1

    def done(self) -> bool:
        return not any(self.plan.values())

    def report(self, seed: int) -> dict:
        return {"seed": seed, "foreign_phase": self.maker.foreign_phase,
                "fuzzed_ticks": self.fuzzed_ticks,
                "sent": {t: dict(c) for t, c in self.sent.items()},
                "refusals_per_subscriber": {t: dict(c) for t, c in self.refusals.items()},
                "ignored": {TASK: dict(self.ignored)},
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
            while not fuzzer.episode_ended and not signals and \
                    time.monotonic() - fuzzer.live_at < GRAPH_SILENT_S:
                executor.spin_once(timeout_sec=0.1)
            text = json.dumps(fuzzer.report(args.seed), indent=1)
            if args.report:
                with open(args.report, "w") as f:
                    f.write(text)
            else:
                print(text)
            # Once (a suite run beside other work), the fuzzer wrote its report and then did not
            # exit within 180 s. Should the way out hang again, every thread's stack is printed
            # and the process ends (exit 1) instead of holding the test until its timeout.
            faulthandler.dump_traceback_later(EXIT_HANG_S, exit=True)
            return 0
        finally:
            # rclpy's order: the executor shut down (it lets go of the node's entities, whose
            # DDS callbacks it had registered) before the node is destroyed, then rclpy itself
            # (ros_session); the executor used to outlive both.
            executor.shutdown()
            fuzzer.destroy_node()


if __name__ == "__main__":
    sys.exit(main())
