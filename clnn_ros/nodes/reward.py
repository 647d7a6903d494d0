"""Reward node: the success counter. Each state's outcome becomes the paper's 1-hot reward R:
[0,1] punishment when the step failed, [1,0] a positive reward every sigma successful steps,
[0,0] otherwise; it also tells the agent when the trial is over.

    python -m clnn_ros.nodes.reward --ros-args -p sigma:=256
"""

from __future__ import annotations

from clnn_ros_msgs.msg import CartPoleState, Reward

from ..core.rln import NONE, ONE_HOT, REWARD_KINDS
from ..init_weights import episode_start
from ..names import REWARD, STATE
from .common import GraphNode, TickJoin, node_main


class RewardNode(GraphNode):
    def __init__(self, **options):
        # reward subscribers: agent, trial manager
        super().__init__("reward", {"reward_pub": (Reward, REWARD, 2)}, **options)
        # a resumed episode (init_weights: a checkpoint) continues a carried success count
        self.counter = episode_start(self.settings["init_weights"], self.settings["seed"],
                                     self.params).success_counter(self.params)
        self.trial = -1
        self.reward_msg = Reward()  # one message object, refilled each tick
        self.join = TickJoin(self, (STATE,), self.on_tick)
        self.subscribe(CartPoleState, STATE, lambda msg: self.join.offer(STATE, msg))

    def on_tick(self, inbox: dict) -> None:
        msg = inbox[STATE]
        if msg.trial != self.trial:  # the trial's first state: no step has been taken yet
            self.trial = msg.trial
            self.counter.begin_trial()
            kind = NONE
        else:
            kind = self.counter.outcome(msg.failed)
        out = self.reward_msg
        out.reward_one_hot, out.kind = ONE_HOT[kind], REWARD_KINDS[kind]
        out.success_counter = self.counter.count
        out.trial_over = msg.failed or msg.successful_steps >= self.params.max_steps
        self.reward_pub.publish(self.stamp(out, msg.tick, msg.trial))

def main() -> None:
    raise SystemExit(node_main(RewardNode))


if __name__ == "__main__":
    main()
