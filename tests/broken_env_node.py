"""An environment node with deliberate contract violations, for tests/test_env_contract.py.

    python tests/broken_env_node.py BUG[,BUG...] --ros-args ...

BUG: no_reset (successful_steps not reset at START), wrong_tick (the observation of tick 2 and
later is published with the tick one too high), extra_value (from tick 2 on, one value more
than its task has), no_exit (ignores EPISODE_END), accept_bad_action
(applies action 2, which the cart-pole lacks, as action 1), silent (never announces readiness),
mute (stops publishing observations at tick 50 but stays alive), crash (raises at start),
default_cart_mass (steps the default cart_mass, not the run's), contract_v1 (stamps its first
observation's header, as a node written against version 1 of the contract did), contract_v3
(speaks version 3 as far as the graph can see: its observations go out on cartpole/state, and
it publishes no env/task), task_volatile (publishes env/task VOLATILE: not latched).
"""

import sys

from clnn_ros.core.params import Params
from clnn_ros.core.physics import CartPole
from clnn_ros.graph.names import OLDER_STATE, STATE, TASK
from clnn_ros.nodes.environment import EnvironmentNode
from clnn_ros.nodes.glue import LOCKSTEP_QOS, run_node
from clnn_ros_msgs.msg import Action, TrialEvent

BUGS = set(sys.argv.pop(1).split(","))


class Unpublished:
    """A publisher that publishes nothing (version 3 had no env/task)."""

    def publish(self, _msg) -> None:
        pass


class BrokenEnvironmentNode(EnvironmentNode):
    def __init__(self, run: dict, **options):
        if "crash" in BUGS:
            raise RuntimeError("a bug at start")
        super().__init__(run, **options)
        if "silent" in BUGS:
            self.readiness.cancel()
        if "default_cart_mass" in BUGS:
            self.env.cartpole = CartPole(self.params.replace(cart_mass=Params().cart_mass))
        refuse, publish = self.refusals.refuse, self.state_pub.publish

        def accept_bad_action(topic: str, msg, reason: str, kind: str = "tick") -> None:
            if "accept_bad_action" in BUGS and isinstance(msg, Action) and msg.action == 2:
                msg.action = 1  # ignores the content rules' verdict
                self.on_action(msg)
                return
            refuse(topic, msg, reason, kind)

        def publish_wrong_tick(msg) -> None:
            if "contract_v1" in BUGS:
                msg.header.stamp = self.get_clock().now().to_msg()
            if "wrong_tick" in BUGS and msg.tick >= 2:
                msg.tick += 1
            if "extra_value" in BUGS and msg.tick >= 2:
                msg.values.append(0.0)
            publish(msg)
        self.refusals.refuse, self.state_pub.publish = accept_bad_action, publish_wrong_tick

    def create_publisher(self, msg_type, topic, qos_profile, **kwargs):
        if "contract_v3" in BUGS and topic == TASK:
            return Unpublished()
        if "contract_v3" in BUGS and topic == STATE:
            topic = OLDER_STATE
        if "task_volatile" in BUGS and topic == TASK:
            qos_profile = LOCKSTEP_QOS
        return super().create_publisher(msg_type, topic, qos_profile, **kwargs)

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
