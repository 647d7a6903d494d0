"""Encoder node: cart-pole state -> spike vector (Table 1, 1 or 2 state variables).

    python -m clnn_ros.nodes.encoder --ros-args -p nsv:=2 -p velocity_edge:=0.5
"""

from __future__ import annotations

from clnn_ros_msgs.msg import CartPoleState, SpikeVector

from ..core.encoder import Encoder
from ..names import SPIKES, STATE
from .common import GraphNode, TickJoin, node_main


class EncoderNode(GraphNode):
    def __init__(self, **options):
        # spike subscribers: agent, trial manager
        super().__init__("encoder", {"spikes_pub": (SpikeVector, SPIKES, 2)}, **options)
        self.encoder = Encoder.from_params(self.params)
        # One message object, refilled each tick (publish serializes it at once); labels fixed.
        self.spikes_msg = SpikeVector(input_labels=self.encoder.labels())
        self.join = TickJoin(self, (STATE,), self.on_tick)
        # content rules (finite, consistent, in range): GraphNode.subscribe
        self.subscribe(CartPoleState, STATE, lambda msg: self.join.offer(STATE, msg))

    def on_tick(self, inbox: dict) -> None:
        msg = inbox[STATE]
        spikes = self.encoder.spikes((msg.cart_position_m, msg.cart_velocity_m_per_s,
                                      msg.pole_angle_deg, msg.pole_angular_velocity_deg_per_s))
        out = self.spikes_msg
        out.spikes, out.spiking_inputs = spikes.tolist(), spikes.nonzero()[0].tolist()
        self.spikes_pub.publish(self.stamp(out, msg.tick, msg.trial))

def main() -> None:
    raise SystemExit(node_main(EncoderNode))


if __name__ == "__main__":
    main()
