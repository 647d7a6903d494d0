"""Environment node: owns the cart-pole, applies actions, publishes the state.

    python -m clnn_ros.nodes.environment --ros-args -p physics:=paper
    python -m clnn_ros.nodes.environment --ros-args -p simulator:=gymnasium

The cart-pole (setting `simulator`) is the core's physics as the model parameters say
(`cartpole`), gymnasium's CartPole-v1 (`gymnasium`: gymnasium.make("CartPole-v1").unwrapped,
its state set directly at START, stepped with action 0 or 1) or an MJCF plant simulated by
MuJoCo (`mujoco`: clnn_ros.core.mujoco_physics). The last two keep their own masses, length,
force, limits and tau (0.02 s: the run's tau must be theirs); their radians become the
message's degrees.

Tick t: on /clock(t) together with either /trial/event START(t) (reset the pole to the trial's
initial angle) or /rln/action(t-1) (apply the force, one physics step), publish
/cartpole/state(t), then (at ticks that are multiples of marker_period_ticks) the cart and pole
drawn for a 3D view on /cartpole/markers(t) (clnn_ros.nodes.markers). Another simulator or a
robot replaces this node by keeping that contract (docs/ENV_CONTRACT.md; the markers are
optional there).
"""

from __future__ import annotations

from clnn_ros_msgs.msg import Action, CartPoleState, TrialEvent
from rclpy.node import Node
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from visualization_msgs.msg import MarkerArray

from ..core.episode import reset_for_trial, trial_start
from ..core.params import ParamError, Params
from ..core.physics import CONTINUE, CartPole
from ..graph.fields import stamp_nanoseconds, tick_nanoseconds, tick_stamp
from ..graph.lockstep import Refusals
from ..graph.names import ACTION, CLOCK, MARKERS, STATE, TRIAL_EVENT
from .glue import (LOCKSTEP_QOS, Readiness, checked, declare_run_parameters,
                   endpoints_matched, ends_with_the_episode, run_node, use_sim_time)
from .markers import CartPoleMarkers


def simulator(name: str, params: Params):
    """(the cart-pole, its pole's half-length and track limit in m, for the markers). Those
    that step their own tau import their engine only when chosen."""
    if name == "gymnasium":
        from ..core.gym_physics import GymCartPole
        cartpole, engine = GymCartPole(), "gymnasium"
        limits = cartpole.env.length, cartpole.env.x_threshold
    elif name == "mujoco":
        from ..core.mujoco_physics import MujocoCartPole
        cartpole, engine = MujocoCartPole(), "MuJoCo"
        limits = cartpole.pole_length, cartpole.track_limit_m
    else:
        return CartPole(params), params.pole_length, params.track_limit_m
    if abs(cartpole.tau - params.tau) > 1e-12:
        raise ParamError(f"tau must be {engine}'s {cartpole.tau} s (one tick = one {engine} "
                         f"step), got {params.tau}")
    return (cartpole, *limits)


class EnvironmentNode(Node):
    def __init__(self, run: dict, **node_options):
        super().__init__("environment", **node_options)
        self.params, settings = declare_run_parameters(self, "environment", run)
        self.tau_ns = tick_nanoseconds(self.params.tau)
        self.cartpole, pole_half_length_m, track_limit_m = simulator(settings["simulator"],
                                                                     self.params)
        self.markers = CartPoleMarkers(pole_half_length_m, track_limit_m)
        self.marker_period = settings["marker_period_ticks"]
        self.tick = 0
        self.trial = -1
        self.successful_steps = 0
        self.trial_over = True  # the first tick is a trial start
        self.over_tick = None  # tick of the last state of the trial that just ended
        self.pending = {}  # this tick's inputs by topic: /clock, and START or the action
        self.state_msg = CartPoleState()
        self.finished, self.failure = Future(), None
        self.refusals = Refusals(self.get_logger().error)
        self.state_pub = self.create_publisher(CartPoleState, STATE, LOCKSTEP_QOS)
        # the markers have no subscriber in the graph; extra_nodes' (the recorder) are waited for
        self.markers_pub = self.create_publisher(MarkerArray, MARKERS, LOCKSTEP_QOS) \
            if self.marker_period else None
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
        # force_direction is -1, 0 or +1 (its content rule)
        if action.force_direction == 0:
            # The agent's answer to a trial's last state. It travels on its own topic, so it may
            # arrive after the next trial's START and clock: match it by its tick alone.
            if action.tick != self.over_tick:
                self.refusals.refuse(ACTION, action, "force_direction 0 answers only the last "
                                                     "state of a trial")
            else:
                self.over_tick = None
        elif self.trial_over:
            self.refusals.refuse(ACTION, action, "the trial is over: no force applies")
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
        status = CONTINUE
        if start is not None:
            reset_for_trial(self.cartpole, start.seed, start.trial,
                            *trial_start(start.seed, self.params, start.trial,
                                         start.initial_angle_deg))
            self.trial, self.successful_steps = start.trial, 0
        else:
            status = self.cartpole.step(1 if action.force_direction > 0 else 0)
            self.successful_steps += status == CONTINUE
        self.trial_over = status != CONTINUE or self.successful_steps >= self.params.max_steps
        if self.trial_over:
            self.over_tick = self.tick
        state = self.state_msg  # one message object, refilled each tick (publish copies it)
        (state.cart_position_m, state.cart_velocity_m_per_s, state.pole_angle_deg,
         state.pole_angular_velocity_deg_per_s) = self.cartpole.state
        state.failure = status  # the physics status is the message's failure code
        state.tick, state.trial = self.tick, self.trial
        state.successful_steps = self.successful_steps
        self.state_pub.publish(state)
        if self.markers_pub and self.tick % self.marker_period == 0:
            self.markers_pub.publish(self.markers.serialized(
                tick_stamp(self.tick, self.tau_ns), state.cart_position_m, state.pole_angle_deg))
        self.tick += 1


def main() -> None:
    raise SystemExit(run_node(EnvironmentNode))


if __name__ == "__main__":
    main()
