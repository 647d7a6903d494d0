"""An environment node with deliberate contract violations, for tests/test_env_contract.py.

    python tests/broken_env_node.py BUG[,BUG...] --ros-args ...

BUG: no_reset (successful_steps not reset at START), wrong_tick (the state of tick 2 and later
is published with the tick one too high), no_exit (ignores EPISODE_END), accept_bad_force
(applies force_direction 5 as +F), silent (never announces readiness), mute (stops publishing
states at tick 50 but stays alive), crash (raises at start), default_cart_mass (steps the default
cart_mass, not the run's), contract_v1 (stamps its first state's header, as a node written
against version 1 of the contract did).
"""

import sys

from clnn_ros.core.params import Params
from clnn_ros.core.physics import CartPole
from clnn_ros.nodes.environment import EnvironmentNode
from clnn_ros.nodes.glue import run_node
from clnn_ros_msgs.msg import Action, TrialEvent

BUGS = set(sys.argv.pop(1).split(","))


class BrokenEnvironmentNode(EnvironmentNode):
    def __init__(self, run: dict, **options):
        if "crash" in BUGS:
            raise RuntimeError("a bug at start")
        super().__init__(run, **options)
        if "silent" in BUGS:
            self.readiness.cancel()
        if "default_cart_mass" in BUGS:
            self.cartpole = CartPole(self.params.replace(cart_mass=Params().cart_mass))
        refuse, publish = self.refusals.refuse, self.state_pub.publish

        def accept_bad_force(topic: str, msg, reason: str, kind: str = "tick") -> None:
            if "accept_bad_force" in BUGS and isinstance(msg, Action) and \
                    msg.force_direction == 5:
                msg.force_direction = 1  # ignores the content rules' verdict
                self.on_action(msg)
                return
            refuse(topic, msg, reason, kind)

        def publish_wrong_tick(msg) -> None:
            if "contract_v1" in BUGS:
                msg.header.stamp = self.get_clock().now().to_msg()
            if "wrong_tick" in BUGS and msg.tick >= 2:
                msg.tick += 1
            publish(msg)
        self.refusals.refuse, self.state_pub.publish = accept_bad_force, publish_wrong_tick

    def on_trial_event(self, event: TrialEvent) -> None:
        if "no_exit" in BUGS and event.event == TrialEvent.EPISODE_END:
            return
        super().on_trial_event(event)

    @property
    def successful_steps(self) -> int:
        return self._steps

    @successful_steps.setter
    def successful_steps(self, value: int) -> None:
        if "no_reset" in BUGS and value == 0 and hasattr(self, "_steps"):
            return  # forgets to reset the count at START
        self._steps = value

    def _advance(self) -> None:
        if "mute" in BUGS and self.tick >= 50:
            self.pending = {}
            return
        super()._advance()


if __name__ == "__main__":
    raise SystemExit(run_node(BrokenEnvironmentNode))
