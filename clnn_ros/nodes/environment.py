"""Environment node: owns the task's environment, applies actions, publishes observations.

    python -m clnn_ros.nodes.environment --ros-args -p physics:=paper
    python -m clnn_ros.nodes.environment --ros-args -p simulator:=gymnasium
    python -m clnn_ros.nodes.environment --ros-args -p task:=gymnasium:Acrobot-v1 -p n_actions:=3

The environment (clnn_ros.tasks.environments) is the run's task: the paper's cart-pole
(setting `simulator`: the core's physics as the model parameters say, `cartpole`; Gymnasium's
CartPole-v1 itself, `gymnasium`; or an MJCF plant simulated by MuJoCo, `mujoco`: the last two
keep their own constants and tau, 0.02 s, and their radians become degrees), or any Gymnasium
task (`task` gymnasium:ID; a Box action space's values in the setting `actions`).

Once, latched: env/task, the task's description (contract version 4). Tick t: on /clock(t)
together with either /trial/event START(t) (reset for the trial) or /rln/action(t-1) (apply it,
one step), publish /env/observation(t); the trial is truncated after max_steps successful
steps. The cart-pole also draws itself for a 3D view on /cartpole/markers(t) at ticks that are
multiples of marker_period_ticks (clnn_ros.nodes.markers). Another simulator, task or robot
replaces this node by keeping that contract (docs/ENV_CONTRACT.md; the markers are optional).
"""

from __future__ import annotations

from array import array

from clnn_ros_msgs.msg import Action, Observation, TaskDescription, TrialEvent
from rclpy.node import Node
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from visualization_msgs.msg import MarkerArray

from ..core.params import ParamError
from ..graph.fields import ACTION_NONE, stamp_nanoseconds, tick_nanoseconds, tick_stamp
from ..graph.lockstep import Refusals
from ..graph.names import ACTION, CLOCK, MARKERS, STATE, TASK, TRIAL_EVENT
from ..graph.task_description import Described
from ..tasks.environments import environment_for
from .glue import (LABELS_QOS, LOCKSTEP_QOS, Readiness, checked, declare_run_parameters,
                   endpoints_matched, ends_with_the_episode, run_node, use_sim_time)
from .markers import CartPoleMarkers


class EnvironmentNode(Node):
    def __init__(self, run: dict, **node_options):
        super().__init__("environment", **node_options)
        self.params, settings = declare_run_parameters(self, "environment", run)
        self.tau_ns = tick_nanoseconds(self.params.tau)
        self.env = environment_for(self.params, settings["simulator"], settings["actions"])
        # the cart-pole draws itself; another task has nothing to draw
        drawn = hasattr(self.env, "pole_half_length_m") and settings["marker_period_ticks"]
        self.markers = CartPoleMarkers(self.env.pole_half_length_m, self.env.track_limit_m) \
            if drawn else None
        self.marker_period = settings["marker_period_ticks"]
        self.tick = 0
        self.trial = -1
        self.successful_steps = 0
        self.trial_over = True  # the first tick is a trial start
        self.over_tick = None  # tick of the last state of the trial that just ended
        self.pending = {}  # this tick's inputs by topic: /clock, and START or the action
        self.state_msg = Observation()
        self.finished, self.failure = Future(), None
        self.refusals = Refusals(self.get_logger().error)
        self.state_pub = self.create_publisher(Observation, STATE, LOCKSTEP_QOS)
        self.create_publisher(TaskDescription, TASK, LABELS_QOS).publish(TaskDescription(
            **Described(self.env.task, self.env.termination_reasons).fields()))
        # the markers have no subscriber in the graph; extra_nodes' (the recorder) are waited for
        self.markers_pub = self.create_publisher(MarkerArray, MARKERS, LOCKSTEP_QOS) \
            if self.markers else None
        inputs = [self.create_subscription(msg_type, topic, checked(topic, self.params,
                                                                    self.refusals, callback),
                                           LOCKSTEP_QOS)
                  for msg_type, topic, callback in ((Clock, CLOCK, self.on_clock),
                                                    (Action, ACTION, self.on_action))]
        # Sim time after the node's own /clock subscription: rclpy's TimeSource subscribes then,
        # and a clock reaches it after the tick's state is out, off the tick's critical path.
        use_sim_time(self, "environment")
        self.ends_with_the_episode = ends_with_the_episode(
            self.finished, self.refusals, lambda: (self.tick, list(self.pending)),
            self.get_logger().warning)
        self.create_subscription(TrialEvent, TRIAL_EVENT, checked(
            TRIAL_EVENT, self.params, self.refusals, self.on_trial_event), LOCKSTEP_QOS)
        # states go to the encoder, the reward node and the trial manager
        outputs = [(self.state_pub, 3)] + ([(self.markers_pub, 0)] if self.markers_pub else [])
        self.readiness = Readiness(self, endpoints_matched(settings["extra_nodes"], outputs,
                                                           inputs),
                                   is_running=lambda: self.tick > 0)

    def on_clock(self, clock: Clock) -> None:
        # a whole tick (its content rule)
        tick = stamp_nanoseconds(clock.clock.sec, clock.clock.nanosec) // self.tau_ns
        if tick != self.tick:
            self.refusals.refuse(CLOCK, clock, f"sim time {clock.clock.sec}."
                                               f"{clock.clock.nanosec:09d} s is not tick "
                                               f"{self.tick}")
            return
        self._offer(CLOCK, clock)

    def on_trial_event(self, event: TrialEvent) -> None:
        self.ends_with_the_episode(event)
        if event.event != TrialEvent.START:
            return
        if event.tick != self.tick or not self.trial_over:
            self.refusals.refuse(TRIAL_EVENT, event, f"START expected only at the tick after a "
                                                     f"trial ends (tick {self.tick})")
        else:  # the angle is inside the limit (its content rule)
            self._offer(TRIAL_EVENT, event)

    def on_action(self, action: Action) -> None:
        # the action exists in the network (its content rule)
        if action.action == ACTION_NONE:
            # The agent's answer to a trial's last state. It travels on its own topic, so it may
            # arrive after the next trial's START and clock: match it by its tick alone.
            if action.tick != self.over_tick:
                self.refusals.refuse(ACTION, action, "ACTION_NONE answers only the last "
                                                     "observation of a trial")
            else:
                self.over_tick = None
        elif self.trial_over:
            self.refusals.refuse(ACTION, action, "the trial is over: no action applies")
        elif action.tick + 1 != self.tick:
            self.refusals.refuse(ACTION, action, f"expected the action of tick {self.tick - 1}")
        else:
            self._offer(ACTION, action)

    def _offer(self, topic: str, msg) -> None:
        if topic in self.pending:
            self.refusals.refuse(topic, msg, f"a second message for tick {self.tick}")
            return
        self.pending[topic] = msg
        if CLOCK in self.pending and (TRIAL_EVENT in self.pending or ACTION in self.pending):
            self._advance()

    def _advance(self) -> None:
        start, action = self.pending.get(TRIAL_EVENT), self.pending.get(ACTION)
        self.pending = {}
        state = self.state_msg  # one message object, refilled each tick (publish copies it)
        try:
            if start is not None:
                values = self.env.start(start.seed, start.trial, start.initial_angle_deg)
                self.trial, self.successful_steps = start.trial, 0
                state.reward, state.terminated, state.truncated, state.termination = 0.0, \
                    False, False, 0
            else:
                values, state.reward, state.terminated, state.truncated, state.termination = \
                    self.env.step(action.action)
        except ParamError as error:  # a start it cannot make again, an observation not numbers
            self.failure = f"tick {self.tick}: {error}"
            self.finished.set_result(1)
            return
        if start is None:
            self.successful_steps += not state.terminated
            state.truncated = bool(state.truncated) or (
                not state.terminated and self.successful_steps >= self.params.max_steps)
        self.trial_over = state.terminated or state.truncated
        if self.trial_over:
            self.over_tick = self.tick
        state.values = array("d", values)  # rclpy takes a float64[] as it stores it
        state.tick, state.trial = self.tick, self.trial
        state.successful_steps = self.successful_steps
        self.state_pub.publish(state)
        if self.markers_pub and self.tick % self.marker_period == 0:
            self.markers_pub.publish(self.markers.serialized(
                tick_stamp(self.tick, self.tau_ns), values[0], values[2]))
        self.tick += 1


def main() -> None:
    raise SystemExit(run_node(EnvironmentNode))


if __name__ == "__main__":
    main()
