"""Trial-manager node: drives the episode. It publishes the sim clock one tick at a time (a
tick is tau = 0.02 s of sim time), starts each trial with the seed's initial angle, counts the
trials, ends the episode, reports progress, and detects a stalled graph.

    python -m clnn_ros.nodes.trial_manager --ros-args -p seed:=1 -p trials:=32 -p out_dir:=out

Tick t is done when it holds the environment's state(t) and the agent's action(t); then it
publishes /clock(t+1), preceded by END/START (or EPISODE_END) events when the trial is over.
When no tick completes for `stall_timeout_s`, it names the first node of the tick's chain whose
message is missing, ends the episode and exits with status 1. A node whose process dies (its
heartbeats stop for a second while the graph stands still) ends the episode the same way, named
at once. With a recorder it keeps the clock at most RECORDER_WINDOW ticks ahead
of the recorder's progress, so that no message is lost to a slow recorder.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np
from clnn_ros_msgs.msg import Action, CartPoleState, Reward, SpikeVector, TrialEvent, WeightSnapshot
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Empty, String, UInt64

from ..core.episode import seed_setup, start_from_setting
from .common import (ACTION, ALIVE, ALIVE_QOS, ALIVE_TIMEOUT_S, CLOCK, GRAPH_NODES,
                     PROGRESS_QOS, READY, READY_QOS, RECORDED, RECORDER_WINDOW, REWARD, SPIKES,
                     STATE, TRIAL_EVENT, WEIGHTS, GraphNode, TickJoin, node_main)

STARTUP_TIMEOUT_S = 60.0  # process start, imports and discovery of the whole graph
CONFIRM_S = 0.3  # a node without heartbeats is dead once the graph has stopped for this long
# Who publishes what within a tick, in causal order: the first one missing went silent.
CHAIN = ((STATE, "environment"), (SPIKES, "encoder"), (REWARD, "reward"), (ACTION, "agent"))


class TrialManagerNode(GraphNode):
    listens_to_trial_events = False

    def __init__(self, **options):
        # /clock: environment; /trial/event: environment, encoder, reward, agent
        super().__init__("trial_manager", {"clock_pub": (Clock, CLOCK, 1),
                                           "event_pub": (TrialEvent, TRIAL_EVENT, 4)}, **options)
        _, self.angles = seed_setup(self.settings["seed"], self.params)
        self.results = []  # (trial, initial angle, steps, end reason)
        self.clock_msg = Clock()
        self.final_weights = None
        self.weights_tick = None
        self.last_trial_tick = None  # set when the last trial is over
        # a resumed episode (init_weights: a checkpoint) starts at the checkpoint's next trial
        self.trial = start_from_setting(self.settings["seed"], self.params,
                                        self.settings["init_weights"])[2]
        self.started_at = None
        self.ready = set()
        self.last_tick = {topic: -1 for topic, _ in CHAIN}
        self.last_progress = time.monotonic()
        self.exit_reason = ""
        self.join = TickJoin(self, (STATE, ACTION), self.on_tick)
        self.subscribe(CartPoleState, STATE, self.seen(STATE))
        self.subscribe(SpikeVector, SPIKES, self.seen(SPIKES))
        self.subscribe(Reward, REWARD, self.seen(REWARD))
        self.subscribe(Action, ACTION, self.seen(ACTION))
        self.subscribe(WeightSnapshot, WEIGHTS, self.on_weights)
        self.create_subscription(String, READY, self.on_ready, READY_QOS)
        self.recorded_tick = -1
        self.held = None  # (tick, starts a trial): the next tick, waiting for the recorder
        self.follows_recorder = "recorder" in self.extra_nodes
        if self.follows_recorder:
            self.create_subscription(UInt64, RECORDED, self.on_recorded, PROGRESS_QOS)
        self.heard = {}  # node: when its last heartbeat came
        self.watched = (*GRAPH_NODES, *sorted(self.extra_nodes))
        for node in self.watched:
            self.create_subscription(Empty, ALIVE + node, self.heartbeat_of(node), ALIVE_QOS)
        self.watchdog = self.create_timer(0.1, self.check)

    def seen(self, topic: str):
        def receive(msg) -> None:
            self.last_tick[topic] = max(self.last_tick[topic], msg.tick)
            if topic in (STATE, ACTION):
                self.join.offer(topic, msg)
        return receive

    def on_ready(self, msg: String) -> None:
        self.ready.add(msg.data)

    def heartbeat_of(self, node: str):
        def heard(_) -> None:
            self.heard[node] = time.monotonic()
        return heard

    def watching_all(self) -> bool:
        """Has each node with a heartbeat publisher (every node of this package; a swapped-in
        environment node may have none, and is then caught by the stall watchdog alone) been
        heard, so that its death can be told from tick 0 on?"""
        return all(node in self.heard for node in self.watched
                   if self.count_publishers(ALIVE + node))

    def dead_node(self, now: float) -> str | None:
        """A node whose heartbeats stopped ALIVE_TIMEOUT_S ago while the graph made no progress
        for CONFIRM_S (on a machine too loaded to beat in time, the graph still ticks)."""
        if now - self.last_progress < CONFIRM_S:
            return None
        return next((node for node, heard in self.heard.items()
                     if now - heard > ALIVE_TIMEOUT_S), None)

    def on_recorded(self, msg: UInt64) -> None:
        if msg.data > self.recorded_tick and self.held is not None:
            self.last_progress = time.monotonic()  # a slow recorder is not a stalled one
        self.recorded_tick = max(self.recorded_tick, msg.data)
        if self.held is not None and self.held[0] <= self.recorded_tick + RECORDER_WINDOW:
            tick, starts_trial = self.held
            self.held = None
            self.advance(tick, starts_trial)

    def on_weights(self, msg: WeightSnapshot) -> None:
        self.final_weights = np.array(msg.weights).reshape(msg.neurons, msg.segments, msg.inputs)
        self.weights_tick = msg.tick
        self.finish_when_weights_arrive()

    def finish_when_weights_arrive(self) -> None:
        """The episode is complete once the agent's weights after the last trial are in (they
        travel on their own topic, so they may arrive after the last action)."""
        if self.last_trial_tick is not None and self.weights_tick == self.last_trial_tick:
            self.stop(0, "completed", self.last_trial_tick)

    def check(self) -> None:
        """Start once every node is ready; afterwards watch for a stall."""
        now = time.monotonic()
        if self.started_at is None:
            if self.publishers_matched() and self.ready >= set(GRAPH_NODES) | self.extra_nodes \
                    and self.watching_all():
                self.started_at = self.last_progress = now
                self.advance(0, starts_trial=True)
            elif now - self.last_progress > STARTUP_TIMEOUT_S:
                missing = sorted((set(GRAPH_NODES) | self.extra_nodes) - self.ready) or [
                    "(subscriptions of /clock or /trial/event)"]
                self.stop(1, f"graph not ready after {STARTUP_TIMEOUT_S:.0f} s: "
                             f"waiting for {', '.join(missing)}")
        elif dead := self.dead_node(now):
            self.stop(1, f"node '{dead}' died at tick {self.join.tick} (no heartbeat for "
                         f"{ALIVE_TIMEOUT_S:g} s)")
        elif now - self.last_progress > self.settings["stall_timeout_s"]:
            silent = "recorder" if self.held is not None else next(
                (node for topic, node in CHAIN if self.last_tick[topic] < self.join.tick),
                "agent")  # all of the tick is in: only the final weights are missing
            self.stop(1, f"stall: node '{silent}' went silent at tick {self.join.tick} "
                         f"(no progress for {self.settings['stall_timeout_s']:g} s)")

    def advance(self, tick: int, starts_trial: bool) -> None:
        """Publish tick `tick` (START first if it starts a trial), unless the recorder is more
        than RECORDER_WINDOW ticks behind: then hold it until the recorder's progress comes."""
        if self.follows_recorder and tick > self.recorded_tick + RECORDER_WINDOW:
            self.held = (tick, starts_trial)
            return
        if starts_trial:
            self.event_pub.publish(self.stamp(TrialEvent(
                event=TrialEvent.START, initial_angle_deg=float(self.angles[self.trial]),
                seed=self.settings["seed"]), tick, self.trial))
        self.publish_clock(tick)

    def publish_clock(self, tick: int) -> None:
        clock = self.clock_msg  # one message object, refilled each tick
        clock.clock.sec, clock.clock.nanosec = divmod(tick * self.tau_ns, 1_000_000_000)
        self.clock_pub.publish(clock)

    def on_tick(self, inbox: dict) -> None:
        state, action = inbox[STATE], inbox[ACTION]
        self.last_progress = time.monotonic()
        tick = state.tick
        if action.force_direction != 0:
            self.advance(tick + 1, starts_trial=False)
            return
        reason = state.failure_reason or "max_steps"
        self.results.append((self.trial, float(self.angles[self.trial]), state.successful_steps,
                             reason))
        self.event_pub.publish(self.stamp(TrialEvent(
            event=TrialEvent.END, initial_angle_deg=float(self.angles[self.trial]),
            successful_steps=state.successful_steps, end_reason=reason,
            seed=self.settings["seed"]), tick, self.trial))
        self.report(tick)
        if self.trial + 1 < len(self.angles):
            self.trial += 1
            self.advance(tick + 1, starts_trial=True)
        else:
            self.last_trial_tick = tick
            self.finish_when_weights_arrive()

    def report(self, tick: int) -> None:
        if not self.settings["progress"]:
            return
        steps = [r[2] for r in self.results]
        rate = tick / max(time.monotonic() - self.started_at, 1e-9)
        print(f"trial {self.trial + 1:4d}/{len(self.angles)}  steps {steps[-1]:6d}  "
              f"mean {np.mean(steps):8.1f}  {rate:7.0f} ticks/s", flush=True)

    def interrupted(self) -> None:
        """Ctrl-C: keep what the run did so far."""
        self.exit_reason = "interrupted"
        self.write_results(self.join.tick)

    def stop(self, exit_code: int, reason: str, tick: int | None = None) -> None:
        """End the episode: tell every node, write the results, finish with `exit_code`."""
        if self.finished.done():
            return
        self.exit_reason = reason
        tick = self.join.tick if tick is None else tick
        self.event_pub.publish(self.stamp(TrialEvent(
            event=TrialEvent.EPISODE_END, end_reason=reason, seed=self.settings["seed"],
            successful_steps=self.results[-1][2] if self.results else 0), tick, self.trial))
        if exit_code:
            self.get_logger().error(reason)
        self.write_results(tick)
        self.finish(exit_code)

    def write_results(self, tick: int) -> None:
        if not self.settings["out_dir"]:
            return
        out = Path(self.settings["out_dir"])
        out.mkdir(parents=True, exist_ok=True)
        with open(out / "trials.csv", "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["seed", "trial", "initial_angle_deg", "steps", "end_reason"])
            writer.writerows([self.settings["seed"], *r] for r in self.results)
        if self.final_weights is not None:
            np.save(out / "final_weights.npy", self.final_weights)
        wall = time.monotonic() - self.started_at if self.started_at else 0.0
        steps = [r[2] for r in self.results]
        (out / "summary.json").write_text(json.dumps({
            "seed": self.settings["seed"], "trials": len(steps),
            "mean_steps": float(np.mean(steps)) if steps else None, "ticks": tick + 1,
            "wall_s": wall, "ticks_per_s": (tick + 1) / wall if wall else None,
            "exit_reason": self.exit_reason}, indent=2))


def main() -> None:
    raise SystemExit(node_main(TrialManagerNode))


if __name__ == "__main__":
    main()
