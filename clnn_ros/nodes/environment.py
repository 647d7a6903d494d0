"""Environment node: owns the cart-pole (core physics), applies actions, publishes the state.

    python -m clnn_ros.nodes.environment --ros-args -p physics:=paper

Tick t: on /clock(t) together with either /trial/event START(t) (reset the pole to the trial's
initial angle) or /rln/action(t-1) (apply the force, one physics step), publish
/cartpole/state(t), then (at ticks that are multiples of marker_period_ticks) the cart and pole
drawn for a 3D view on /cartpole/markers(t) (clnn_ros.nodes.markers). Another simulator or a
robot replaces this node by keeping that contract (docs/ENV_CONTRACT.md; the markers are
optional there).
"""

from __future__ import annotations

from clnn_ros_msgs.msg import Action, CartPoleState, TrialEvent
from rosgraph_msgs.msg import Clock
from visualization_msgs.msg import MarkerArray

from ..core.params import ParamError
from ..core.physics import CONTINUE, CartPole
from ..message_fields import FAILURE_REASONS
from ..names import ACTION, CLOCK, MARKERS, STATE, TRIAL_EVENT
from .common import GraphNode, node_main
from .markers import FRAME, CartPoleMarkers


class EnvironmentNode(GraphNode):
    def __init__(self, **options):
        # state subscribers: encoder, reward, trial manager
        super().__init__("environment", {"state_pub": (CartPoleState, STATE, 3)}, **options)
        self.marker_period = self.settings["marker_period_ticks"]
        if self.marker_period:  # no subscriber in the graph; extra_nodes' (the recorder) waited for
            self.add_publisher("markers_pub", MarkerArray, MARKERS, 0)
        self.cartpole = CartPole(self.params)
        self.markers = CartPoleMarkers(self.params.pole_length, self.params.track_limit_m)
        self.tick = 0
        self.trial = -1
        self.successful_steps = 0
        self.trial_over = True  # the first tick is a trial start
        self.over_tick = None  # tick of the last state of the trial that just ended
        self.pending = {}  # this tick's inputs by topic: /clock, and START or the action
        self.state_msg = CartPoleState()
        self.state_msg.header.frame_id = FRAME  # the frame cart_position_m is measured in
        self.subscribe(Clock, CLOCK, self.on_clock)
        self.subscribe(Action, ACTION, self.on_action)

    def use_simulator(self, cartpole, name: str, pole_half_length_m: float,
                      track_limit_m: float) -> None:
        """Swap the paper's cart-pole for another simulator with the same interface that steps
        its own fixed tau (gymnasium's, MuJoCo's): one tick is one of its steps, so the run's
        tau must be the simulator's. The markers draw its pole and track."""
        if abs(cartpole.tau - self.params.tau) > 1e-12:
            raise ParamError(f"tau must be {name}'s {cartpole.tau} s (one tick = one {name} "
                             f"step), got {self.params.tau}")
        self.cartpole = cartpole
        self.markers = CartPoleMarkers(pole_half_length_m, track_limit_m)

    def on_clock(self, clock: Clock) -> None:
        # a whole tick (content rules: GraphNode.subscribe)
        tick = (clock.clock.sec * 1_000_000_000 + clock.clock.nanosec) // self.tau_ns
        if tick != self.tick:
            self.refuse(CLOCK, clock, f"sim time {clock.clock.sec}.{clock.clock.nanosec:09d} s is "
                                      f"not tick {self.tick}")
            return
        self._offer(CLOCK, clock)

    def current_tick(self) -> int:
        return self.tick

    def on_trial_event(self, event: TrialEvent) -> None:
        super().on_trial_event(event)
        if event.event != TrialEvent.START:
            return
        if event.tick != self.tick or not self.trial_over:
            self.refuse(TRIAL_EVENT, event, f"START expected only at the tick after a trial "
                                            f"ends (tick {self.tick})")
        else:  # the angle is inside the limit (content rules: GraphNode.subscribe)
            self._offer(TRIAL_EVENT, event)

    def on_action(self, action: Action) -> None:
        # force_direction is -1, 0 or +1 (content rules: GraphNode.subscribe)
        if action.force_direction == 0:
            # The agent's answer to a trial's last state. It travels on its own topic, so it may
            # arrive after the next trial's START and clock: match it by its tick alone.
            if action.tick != self.over_tick:
                self.refuse(ACTION, action, "force_direction 0 answers only the last state of a "
                                            "trial")
            else:
                self.over_tick = None
        elif self.trial_over:
            self.refuse(ACTION, action, "the trial is over: no force applies")
        elif action.tick + 1 != self.tick:
            self.refuse(ACTION, action, f"expected the action of tick {self.tick - 1}")
        else:
            self._offer(ACTION, action)

    def _offer(self, topic: str, msg) -> None:
        if topic in self.pending:
            self.refuse(topic, msg, f"a second message for tick {self.tick}")
            return
        self.pending[topic] = msg
        if CLOCK in self.pending and (TRIAL_EVENT in self.pending or ACTION in self.pending):
            self._advance()

    def _advance(self) -> None:
        start, action = self.pending.get(TRIAL_EVENT), self.pending.get(ACTION)
        self.pending = {}
        status = CONTINUE
        if start is not None:
            self.cartpole.reset(start.initial_angle_deg)
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
        state.failed, state.failure_reason = status != CONTINUE, FAILURE_REASONS[status]
        state.successful_steps = self.successful_steps
        self.state_pub.publish(self.stamp(state, self.tick, self.trial))
        if self.marker_period and self.tick % self.marker_period == 0:
            self.markers_pub.publish(self.markers.update(
                state.header.stamp, state.cart_position_m, state.pole_angle_deg))
        self.tick += 1


def main() -> None:
    raise SystemExit(node_main(EnvironmentNode))


if __name__ == "__main__":
    main()
