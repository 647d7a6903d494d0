"""Encoder node: cart-pole state -> spike vector (Table 1, 1 to 4 state variables).

    python -m clnn_ros.nodes.encoder --ros-args -p nsv:=2 -p velocity_edge:=0.5

Subscribes cartpole/state(t); publishes rln/spikes(t), the 1-hot code of each encoded state
variable, and once, latched, rln/input_labels: what each input means. Ends on trial/event
EPISODE_END.
"""

from __future__ import annotations

from clnn_ros_msgs.msg import CartPoleState, InputLabels, SpikeVector, TrialEvent
from rclpy.node import Node
from rclpy.task import Future

from ..core.encoder import Encoder
from ..graph.lockstep import Refusals, TickJoin
from ..graph.names import INPUT_LABELS, SPIKES, STATE, TRIAL_EVENT
from .glue import (LABELS_QOS, LOCKSTEP_QOS, Readiness, checked, declare_run_parameters,
                   endpoints_matched, ends_with_the_episode, run_node, use_sim_time)


class EncoderNode(Node):
    def __init__(self, run: dict, **node_options):
        super().__init__("encoder", **node_options)
        self.params, settings = declare_run_parameters(self, "encoder", run)
        use_sim_time(self, "encoder")
        self.encoder = Encoder.from_params(self.params)
        self.finished, self.failure = Future(), None
        self.refusals = Refusals(self.get_logger().error)
        self.join = TickJoin((STATE,), self.on_tick, self.refusals)
        self.spikes_msg = SpikeVector()  # one message object, refilled each tick
        self.spikes_pub = self.create_publisher(SpikeVector, SPIKES, LOCKSTEP_QOS)
        self.create_publisher(InputLabels, INPUT_LABELS, LABELS_QOS).publish(
            InputLabels(labels=self.encoder.labels()))
        state_sub = self.create_subscription(
            CartPoleState, STATE,
            checked(STATE, self.params, self.refusals, lambda msg: self.join.offer(STATE, msg)),
            LOCKSTEP_QOS)
        self.create_subscription(TrialEvent, TRIAL_EVENT, checked(
            TRIAL_EVENT, self.params, self.refusals,
            ends_with_the_episode(self.finished, self.refusals, self.join.standing,
                                  self.get_logger().warning)),
            LOCKSTEP_QOS)
        # spikes go to the agent and the trial manager
        self.readiness = Readiness(self, endpoints_matched(
            settings["extra_nodes"], [(self.spikes_pub, 2)], [state_sub]),
            is_running=lambda: self.join.tick > 0)

    def on_tick(self, inbox: dict) -> None:
        msg = inbox[STATE]
        spikes = self.encoder.spikes((msg.cart_position_m, msg.cart_velocity_m_per_s,
                                      msg.pole_angle_deg, msg.pole_angular_velocity_deg_per_s))
        out = self.spikes_msg
        out.tick, out.trial, out.spikes = msg.tick, msg.trial, spikes.tobytes()
        self.spikes_pub.publish(out)


def main() -> None:
    raise SystemExit(run_node(EncoderNode))


if __name__ == "__main__":
    main()
