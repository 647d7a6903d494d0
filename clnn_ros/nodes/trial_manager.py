"""Trial-manager node: drives the episode. It publishes the sim clock one tick at a time (a
tick is tau = 0.02 s of sim time), starts each trial with the seed's initial angle, counts the
trials, ends the episode, reports progress, and detects a stalled graph.

    python -m clnn_ros.nodes.trial_manager --ros-args -p seed:=1 -p trials:=32 -p out_dir:=out

Before the first tick it checks the environment's task (env/task, contract version 4) against
the run's and waits for each node by its name (a renamed environment or one of an older version
is named as such). Tick t is done when it holds observation(t) and action(t); then it publishes
clock(t+1), preceded by END/START (or EPISODE_END) events when the trial is over.

What ends an episode early, with exit status 1 and the node to blame:
* a stall: no tick completes for `stall_timeout_s` of its own running time (its own pause or
  starvation does not count); the node named is the first of the tick's chain whose message for
  the tick is missing;
* a node of `external_nodes` that leaves the ROS graph (run_all or launch see the exit of the
  nodes they started; a paused one that drops out is alive);
* another graph of the same names in the namespace and domain (its claim, GraphClaim; its
  lockstep traffic before this graph's first tick; names two nodes carry for `stall_timeout_s`
  with no other trial manager about: SharedNames): NOT_STARTED, the run abandoned with no
  EPISODE_END (the other's nodes would obey it); a node of `external_nodes` not there within
  `stall_timeout_s` once the rest is up (the others are waited for as long as they take);
* a foreign publisher on a graph topic once running (graph.watch: named with each graph topic it
  publishes on, looked at once its endpoint matches), unless allow_foreign_publishers: then
  the run goes on and ends "tainted", never "completed".
With a recorder it keeps the clock at most RECORDER_WINDOW ticks ahead of the recorder's
progress. Results go to out_dir as each trial ends (trials.csv) and at the end
(final_weights.npy, summary.json).
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np
from clnn_ros_msgs.msg import (Action, Observation, Reward, SpikeVector, TaskDescription,
                               TrialEvent, WeightSnapshot)
from rosgraph_msgs.msg import Clock
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import String, UInt64

from ..core.episode import initial_angles
from ..graph.fields import ACTION_NONE, COMPLETED, REACHED_MAX_STEPS, tick_nanoseconds, tick_stamp
from ..graph.lockstep import Refusals, RunningTime, TickJoin
from ..graph.names import (ACTION, CLOCK, ENVIRONMENT, GRAPH_NODES, NOT_STARTED, OLDER_STATE,
                           PUBLISHED_BY, READY, RECORDED, RECORDER, REWARD, SPIKES, STATE, TASK,
                           TRIAL_EVENT, TRIAL_MANAGER, WEIGHTS)
from ..graph.task_description import OLDER_CONTRACT, described, description_problem
from ..graph.qos import RECORDER_WINDOW
from ..graph.run import NODE_PARAMETERS, names_list
from ..graph.watch import (another_graph, describe_foreign, foreign_publishers, gone, named_twice,
                           names_pending, renamed_environment)
from ..core.init_weights import episode_start
from .trial_files import TrialFiles, progress_line
from .glue import (LABELS_QOS, LOCKSTEP_QOS, PROGRESS_QOS, READY_QOS, GraphClaim, Pace, Readiness,
                   SharedNames, checked, declare_run_parameters, endpoints_matched,
                   publishers_by_topic, run_node, steady_clock, use_sim_time)

WATCHDOG_S = 0.1
GRAPH_CHECK_S = 0.5  # how often the ROS graph is looked at once running (before: every check)
WAITING_NOTE_S = 10.0  # while the graph is not ready, a note of what it waits for this often
# Who publishes what within a tick, in causal order: the first one missing went silent.
CHAIN = (STATE, SPIKES, REWARD, ACTION)


class TrialManagerNode(Node):
    def __init__(self, run: dict, **node_options):
        super().__init__(TRIAL_MANAGER, **node_options)  # its time is its own: it has the clock
        self.params, self.settings = declare_run_parameters(self, TRIAL_MANAGER, run)
        use_sim_time(self, TRIAL_MANAGER)
        self.tau_ns = tick_nanoseconds(self.params.tau)
        self.extra_nodes = names_list(self.settings["extra_nodes"])
        self.finished, self.failure = Future(), None
        self.refusals = Refusals(self.get_logger().error)
        self.angles = initial_angles(self.settings["seed"], self.params)
        self.results = []  # (trial, initial angle, steps, end reason)
        self.files = TrialFiles(self.settings["out_dir"], self.settings["seed"],
                                self.get_logger().error)
        self.clock_msg = Clock()
        self.final_weights = self.weights_tick = None
        self.trial_end_tick = None  # the last tick of the last trial that ended
        self.last_trial_tick = None  # set when the last trial is over
        # a resumed episode (init_weights: a checkpoint) starts at the checkpoint's next trial
        self.trial = episode_start(self.settings["init_weights"], self.settings["seed"],
                                   self.params, NODE_PARAMETERS[TRIAL_MANAGER]).first_trial
        self.started_at, self.ready = None, set()
        self.external_nodes = names_list(self.settings["external_nodes"])
        self.expected = set(GRAPH_NODES) | self.extra_nodes
        self.in_graph = set()  # nodes of the graph seen in the ROS graph
        self.externals_awaited_since, self.unnamed_s, self.topic_publishers = None, 0.0, {}
        self.last_note = self.last_graph_check = time.monotonic()
        self.running = RunningTime(cap=2 * WATCHDOG_S)
        self.stalled_s = 0.0  # running time of this node without progress
        self.shared_names = []  # before the start: names two nodes carry
        self.tainted = self.foreign_seen = None  # a foreign publisher seen on a graph topic
        self.named_twice = set()  # graph names two nodes carried once the graph ran
        self.exit_reason = ""
        self.join = TickJoin((STATE, ACTION), self.on_tick, self.refusals)
        self.task = None  # the environment's (env/task), checked against the run's parameters
        self.create_subscription(TaskDescription, TASK, self.on_task, LABELS_QOS)
        self.current = {topic: -1 for topic in CHAIN}  # the last tick each topic gave
        self.clock_pub = self.create_publisher(Clock, CLOCK, LOCKSTEP_QOS)
        self.event_pub = self.create_publisher(TrialEvent, TRIAL_EVENT, LOCKSTEP_QOS)
        self.look_again = False  # a publisher that joined is looked at once its endpoint matches
        joined = SubscriptionEventCallbacks(matched=self.on_matched)
        inputs = [self.create_subscription(msg_type, topic, checked(
            topic, self.params, self.refusals,
            self.on_weights if topic == WEIGHTS else self.seen(topic)), LOCKSTEP_QOS,
            event_callbacks=joined) for msg_type, topic in (
            (Observation, STATE), (SpikeVector, SPIKES), (Reward, REWARD), (Action, ACTION),
            (WeightSnapshot, WEIGHTS))]
        # the clock goes to the environment; trial events to the four other nodes
        self.matched = endpoints_matched(self.settings["extra_nodes"],
                                         [(self.clock_pub, 1), (self.event_pub, 4)], inputs)
        self.create_subscription(String, READY, lambda msg: self.ready.add(msg.data), READY_QOS)
        self.readiness = Readiness(self, self.matched, is_running=lambda: self.join.tick > 0)
        self.claim = GraphClaim(self, self.on_other_graph)
        self.names = SharedNames(self, self.claim, self.settings["stall_timeout_s"])
        self.pace = Pace(self, self.settings["rate_hz"], self.publish_tick)
        self.recorded_tick = -1
        self.held = None  # (tick, starts a trial): the next tick, waiting for the recorder
        self.follows_recorder = RECORDER in self.extra_nodes
        self.recorder_out = False  # the recorder dropped out of the ROS graph (watch_recorder)
        if self.follows_recorder:
            self.create_subscription(UInt64, RECORDED, self.on_recorded, PROGRESS_QOS)
        self.watchdog = self.create_timer(WATCHDOG_S, self.check, clock=steady_clock())

    def seen(self, topic: str):
        """State and action make the tick (TickJoin); spikes and reward, watched for the blame,
        come in order, one per tick (each may come after the action); before the start, none."""
        def receive(msg) -> None:
            if self.started_at is None:  # its nodes wait for its first clock: another graph's
                self.stop(NOT_STARTED, another_graph(self.get_namespace(), f"its {topic} came "
                                                     f"before this graph's first tick"))
            elif topic == STATE and (problem := self.task.observation_problem(msg.values)):
                self.refusals.refuse(topic, msg, problem, kind="content")  # as the encoder does
            elif (self.join.offer(topic, msg) if topic in (STATE, ACTION) else
                  msg.tick == self.current[topic] + 1 <= self.join.tick):
                self.current[topic] = msg.tick
            elif topic not in (STATE, ACTION):  # (TickJoin refuses its own)
                self.refusals.refuse(topic, msg, f"expected tick {self.current[topic] + 1}")
        return receive

    def on_recorded(self, msg: UInt64) -> None:
        if msg.data > self.recorded_tick and self.held is not None:
            self.stalled_s = 0.0  # a slow recorder is not a stalled one
        self.release_held(msg.data)

    def release_held(self, recorded_tick: int) -> None:
        self.recorded_tick = max(self.recorded_tick, recorded_tick)
        if self.held is not None and self.held[0] <= self.recorded_tick + RECORDER_WINDOW:
            tick, starts_trial = self.held
            self.held = None
            self.advance(tick, starts_trial)

    def on_weights(self, msg: WeightSnapshot) -> None:
        """The weights after a trial: of the tick being completed, or of the trial's last tick."""
        if msg.tick != self.join.tick and (msg.tick != self.trial_end_tick or
                                           self.weights_tick == msg.tick):
            self.refusals.refuse(WEIGHTS, msg, f"expected weights of tick {self.trial_end_tick}")
            return
        self.final_weights = np.array(msg.weights).reshape(msg.neurons, msg.segments, msg.inputs)
        self.weights_tick = msg.tick
        self.finish_when_weights_arrive()

    def finish_when_weights_arrive(self) -> None:
        """Complete once the weights after the last trial are in (they may follow its action)."""
        if self.last_trial_tick is not None and self.weights_tick == self.last_trial_tick:
            self.stop(*((1, f"tainted: {self.tainted}") if self.tainted else (0, COMPLETED)),
                      self.last_trial_tick)  # a tainted run is never reported as completed

    # --- the watchdog -------------------------------------------------------------------------

    def check(self) -> None:
        """Start once the graph is ready; afterwards watch for a stall and for nodes leaving."""
        now = time.monotonic()
        running = self.running.since_last_check()  # a pause of this process is no stall
        if now - self.last_graph_check >= GRAPH_CHECK_S or self.started_at is None or \
                self.look_again:
            self.last_graph_check = now
            if problem := self.graph_problem():
                self.stop(1, problem)
                return
        if self.started_at is None:
            self.check_start(now, running)
            return
        self.stalled_s += running
        if self.stalled_s > self.settings["stall_timeout_s"]:
            self.stop(1, self.stall_reason())

    def graph_problem(self) -> str | None:
        """Shared names (held before the start, a taint after), a node that left, a forger."""
        namespace = self.get_namespace()
        present = Counter(name for name, ns in self.get_node_names_and_namespaces()
                          if ns == namespace)
        twice = named_twice(present, self.expected | {TRIAL_MANAGER})
        if self.started_at is None:  # check_start holds the start while names are shared
            self.shared_names = twice
        elif twice := self.names.unexplained(twice):
            # A graph that starts beside this one gives way (on_other_graph, in its own trial
            # manager): this one goes on, says what it saw, and never reports "completed".
            for name in sorted(set(twice) - self.named_twice):
                self.get_logger().warning(f"a second node named '{name}' joined namespace "
                                          f"{namespace} at tick {self.join.tick}")
            self.named_twice |= set(twice)
            self.tainted = self.tainted or f"a second node named '{twice[0]}' ran in namespace " \
                f"{namespace}: its messages may have been taken for the graph's"
        if self.follows_recorder and RECORDER in self.in_graph:
            self.watch_recorder(bool(present[RECORDER]))
        self.in_graph |= {n for n in self.expected if present[n]}
        if left := gone(self.in_graph, present, self.external_nodes):
            return f"node '{left[0]}' left the ROS graph at tick {self.join.tick}"
        self.topic_publishers = publishers = publishers_by_topic(self, PUBLISHED_BY)
        self.look_again = names_pending(publishers)  # a name still to come: look next check
        if self.started_at is None:  # before the first tick its traffic judges it (seen): one
            return None  # outcome, not a race of its name's discovery and its first message
        foreign = foreign_publishers(publishers, namespace)
        if foreign and not self.tainted and describe_foreign(foreign) != self.foreign_seen:
            # its other topics' endpoints may come a moment later: named once it holds still
            self.foreign_seen, self.look_again = describe_foreign(foreign), True
        elif foreign and not self.tainted:
            self.tainted = self.foreign_seen
            if not self.settings["allow_foreign_publishers"]:
                return f"{self.tainted} at tick {self.join.tick} (its messages may have been " \
                       f"taken for the graph's; allow_foreign_publishers: go on, tainted)"
            self.get_logger().warning(f"{self.tainted}: the run goes on, its results tainted")
        return None

    def on_matched(self, status) -> None:
        self.look_again = self.look_again or status.current_count_change > 0

    def on_other_graph(self, started_first: bool) -> None:
        """The claim of another graph's trial manager in this namespace and domain."""
        namespace = self.get_namespace()
        if started_first:
            self.stop(NOT_STARTED, another_graph(namespace, "its trial manager started first"))
        else:
            self.get_logger().warning(f"a second graph started in namespace {namespace} at tick "
                                      f"{self.join.tick}: it gives way")

    def watch_recorder(self, present: bool) -> None:
        """A recorder paused past its DDS lease drops out: the graph goes on until it is back."""
        if not present and not self.recorder_out:
            self.recorder_out = True
            self.get_logger().warning(f"the recorder left the ROS graph at tick {self.join.tick} "
                                      f"(paused past its lease, or ended): unrecorded from now")
            if self.held is not None:
                self.release_held(self.held[0] - RECORDER_WINDOW)
        elif present and self.recorder_out:
            self.recorder_out = False
            self.recorded_tick = max(self.recorded_tick, self.join.tick)  # its progress comes

    def on_task(self, msg: TaskDescription) -> None:
        if self.task is None and (problem := description_problem(msg, self.params)):
            self.stop(1, f"the environment node's task (env/task) does not fit the run: {problem}")
        elif self.task is None:
            self.task = described(msg)

    def check_start(self, now: float, running: float) -> None:
        if self.task is None and self.count_publishers(self.resolve_topic_name(OLDER_STATE)):
            self.stop(1, OLDER_CONTRACT)
            return
        contested = self.claim.contested()
        hold, give_way = self.names.check(self.shared_names, contested, running)
        if give_way:
            self.stop(NOT_STARTED, another_graph(self.get_namespace(), give_way))
            return
        if hold:  # whose announcement? (nodes repeat)
            self.ready.clear()
        missing = self.expected - self.ready
        if not (missing or hold) and self.matched() and self.task is not None:
            if self.expected <= self.in_graph:  # each by its name, not only its announcement
                self.started_at = now
                self.advance(0, starts_trial=True)
            else:  # announced, not in the ROS graph by its name (yet): renamed, or a slow name
                self.unnamed_s += running
                renamed = renamed_environment(self.topic_publishers, self.get_namespace(),
                                              ENVIRONMENT in self.in_graph)
                if renamed and self.unnamed_s > self.settings["stall_timeout_s"]:
                    self.stop(1, renamed)
            return
        absent = (self.external_nodes & missing) - self.in_graph
        if absent and (self.expected - self.external_nodes) <= self.in_graph:
            # All run_all started is up: the nodes started by someone else get the stall timeout
            self.externals_awaited_since = (self.externals_awaited_since or 0.0) + running
            if self.externals_awaited_since > self.settings["stall_timeout_s"]:
                self.stop(1, f"no {', '.join(sorted(absent))} node appeared in namespace "
                             f"{self.get_namespace()} within {self.settings['stall_timeout_s']:g}"
                             f" s (start it yourself: docs/ENV_CONTRACT.md)")
        elif now - self.last_note >= WAITING_NOTE_S:
            self.last_note = now
            self.get_logger().warning(f"waiting for {', '.join(sorted(missing)) or 'matching'}"
                                      + ("" if self.task else f", the task on {TASK}"))

    def stall_reason(self) -> str:
        """The node whose message for the current tick is missing, first in the chain."""
        tick, timeout = self.join.tick, self.settings["stall_timeout_s"]
        if self.held is not None:
            return f"stall: node '{RECORDER}' fell behind at tick {self.recorded_tick} " \
                   f"(no progress for {timeout:g} s)"
        # all of the tick in: only the final weights are missing
        topic = next((t for t in CHAIN if self.current[t] < tick), WEIGHTS)
        refused = f"; last refused {topic}: {self.refusals.last[topic]}" \
            if topic in self.refusals.last else ""
        return f"stall: node '{PUBLISHED_BY[topic]}' went silent at tick {tick} (no " \
               f"progress for {timeout:g} s{refused})"

    # --- the clock ----------------------------------------------------------------------------

    def advance(self, tick: int, starts_trial: bool) -> None:
        """Publish tick `tick` (START first), unless held for a recorder RECORDER_WINDOW behind."""
        if self.follows_recorder and not self.recorder_out and \
                tick > self.recorded_tick + RECORDER_WINDOW:
            self.held = (tick, starts_trial)
            return
        self.pace.offer(tick, starts_trial)  # at most rate_hz ticks a second (0: unpaced)

    def publish_tick(self, tick: int, starts_trial: bool) -> None:
        self.stalled_s = 0.0  # a paced tick's wait is no stall
        if starts_trial:
            self.event_pub.publish(TrialEvent(
                tick=tick, trial=self.trial, event=TrialEvent.START,
                initial_angle_deg=float(self.angles[self.trial]), seed=self.settings["seed"]))
        clock = self.clock_msg  # one message object, refilled each tick
        clock.clock.sec, clock.clock.nanosec = tick_stamp(tick, self.tau_ns)
        self.clock_pub.publish(clock)

    def on_tick(self, inbox: dict) -> None:
        state, action, tick = inbox[STATE], inbox[ACTION], inbox[STATE].tick
        self.stalled_s = 0.0
        if action.action != ACTION_NONE:
            self.advance(tick + 1, starts_trial=False)
            return
        reason = self.task.end_reason(state.termination) if state.terminated else REACHED_MAX_STEPS
        self.trial_end_tick = tick
        self.results.append((self.trial, float(self.angles[self.trial]), state.successful_steps,
                             reason))
        self.event_pub.publish(TrialEvent(
            tick=tick, trial=self.trial, event=TrialEvent.END,
            initial_angle_deg=float(self.angles[self.trial]),
            successful_steps=state.successful_steps, end_reason=reason,
            seed=self.settings["seed"]))
        self.report(tick)
        if problem := self.files.trials(self.results):
            self.stop(1, problem, tick)
        elif self.trial + 1 < len(self.angles):
            self.trial += 1
            self.advance(tick + 1, starts_trial=True)
        else:
            self.last_trial_tick = tick
            self.finish_when_weights_arrive()

    def report(self, tick: int) -> None:
        if self.settings["progress"]:
            rate = tick / max(time.monotonic() - self.started_at, 1e-9)
            print(progress_line(self.trial + 1, len(self.angles), [r[2] for r in self.results],
                                rate), flush=True)

    # --- the end ------------------------------------------------------------------------------

    def interrupted(self) -> None:
        """Ctrl-C: keep what the run did so far."""
        self.exit_reason = "interrupted"
        self.save_results(self.join.tick, 0)  # a requested stop: run_node exits with 0

    def stop(self, exit_code: int, reason: str, tick: int | None = None) -> None:
        """End the episode: tell the nodes (not when it gives way: the other graph's would obey
        it too), withdraw the claim (its DDS goodbye may be lost), write the results, finish."""
        if self.finished.done():
            return
        self.claim.withdraw()
        tick = self.join.tick if tick is None else tick
        if exit_code != NOT_STARTED:
            self.event_pub.publish(TrialEvent(
                tick=tick, trial=self.trial, event=TrialEvent.EPISODE_END, end_reason=reason,
                seed=self.settings["seed"],
                successful_steps=self.results[-1][2] if self.results else 0))
        self.exit_reason = reason
        if (problem := self.save_results(tick, exit_code)) and not exit_code:
            exit_code, reason = 1, problem
            self.exit_reason = reason
        if exit_code:
            self.get_logger().error(reason)
        self.finished.set_result(exit_code)

    def save_results(self, tick: int, exit_status: int) -> str | None:
        ran = (tick + 1, time.monotonic() - self.started_at) if self.started_at else (0, 0.0)
        return self.files.results(self.results, self.final_weights, *ran, self.exit_reason,
                                  exit_status)


def main() -> None:
    raise SystemExit(run_node(TrialManagerNode, on_interrupt=TrialManagerNode.interrupted))


if __name__ == "__main__":
    main()
