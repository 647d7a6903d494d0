"""An environment node with deliberate contract violations, for tests/test_env_contract.py.

    python tests/broken_env_node.py BUG[,BUG...] --ros-args ...

BUG: no_reset (successful_steps not reset at START), wrong_tick (the state of tick 2 and later
is published with the tick one too high), no_exit (ignores EPISODE_END), accept_bad_force
(applies force_direction 5 as +F), silent (never announces readiness), mute (stops publishing
states at tick 50 but stays alive), crash (raises at start).
"""

import sys

from clnn_ros.nodes.common import node_main
from clnn_ros.nodes.environment import EnvironmentNode
from clnn_ros_msgs.msg import Action, TrialEvent

BUGS = set(sys.argv.pop(1).split(","))


class BrokenEnvironmentNode(EnvironmentNode):
    def __init__(self, **options):
        if "crash" in BUGS:
            raise RuntimeError("a bug at start")
        super().__init__(**options)
        if "silent" in BUGS:
            self._ready_timer.cancel()

    def on_trial_event(self, event: TrialEvent) -> None:
        if "no_exit" in BUGS and event.event == TrialEvent.EPISODE_END:
            return
        super().on_trial_event(event)

    def refuse(self, topic: str, msg, reason: str, kind: str = "tick") -> None:
        if "accept_bad_force" in BUGS and isinstance(msg, Action) and msg.force_direction == 5:
            msg.force_direction = 1  # ignores the content rules' verdict
            super().on_action(msg)
            return
        super().refuse(topic, msg, reason, kind)

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

    def stamp(self, msg, tick: int, trial: int):
        if "wrong_tick" in BUGS and tick >= 2:
            tick += 1
        return super().stamp(msg, tick, trial)


if __name__ == "__main__":
    raise SystemExit(node_main(BrokenEnvironmentNode))
