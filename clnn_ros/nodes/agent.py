"""Agent node: two RLNs. Spike vector + reward of a tick -> three-factor update, inference,
tagging -> action. At the end of each trial it publishes its weights.

    python -m clnn_ros.nodes.agent --ros-args -p seed:=1 -p nsv:=1
"""

from __future__ import annotations

import numpy as np
from clnn_ros_msgs.msg import Action, Reward, SpikeVector, WeightSnapshot

from ..core.episode import seed_setup
from ..core.rln import ONE_HOT, REWARD_KINDS, RLNAgent
from .common import ACTION, REWARD, SPIKES, WEIGHTS, GraphNode, TickJoin, node_main


class AgentNode(GraphNode):
    def __init__(self, **options):
        # action subscribers: environment, trial manager; weights: trial manager
        super().__init__("agent", {"action_pub": (Action, ACTION, 2),
                                   "weights_pub": (WeightSnapshot, WEIGHTS, 1)}, **options)
        weights, _ = seed_setup(self.settings["seed"], self.params)
        self.agent = RLNAgent(self.params, weights, seed=self.settings["seed"])
        self.trial = -1
        self.action_msg = Action()  # one message object, refilled each tick
        self.join = TickJoin(self, (SPIKES, REWARD), self.on_tick)
        self.subscribe(SpikeVector, SPIKES, self.on_spikes)
        self.subscribe(Reward, REWARD, self.on_reward)

    def on_spikes(self, msg: SpikeVector) -> None:
        spikes = msg.spikes
        if len(spikes) != self.params.n_inputs:
            self.refuse(SPIKES, msg, f"{len(spikes)} spikes, the network has "
                                     f"{self.params.n_inputs} inputs")
        elif max(spikes, default=0) > 1 or sum(spikes) != self.params.nsv:
            self.refuse(SPIKES, msg, f"not a 1-hot code per state variable: {list(msg.spikes)}")
        else:
            self.join.offer(SPIKES, msg)

    def on_reward(self, msg: Reward) -> None:
        if msg.kind not in REWARD_KINDS or tuple(msg.reward_one_hot) != \
                ONE_HOT[REWARD_KINDS.index(msg.kind)]:
            self.refuse(REWARD, msg, f"kind {msg.kind!r} with code {list(msg.reward_one_hot)}")
        else:
            self.join.offer(REWARD, msg)

    def on_tick(self, inbox: dict) -> None:
        spikes, reward = inbox[SPIKES], inbox[REWARD]
        if reward.trial != self.trial:  # a trial's first tick: counters restart, nothing to learn
            self.trial = reward.trial
            self.agent.begin_trial()
        else:
            self.agent.learn(REWARD_KINDS.index(reward.kind))
        action = self.action_msg
        if reward.trial_over:  # only learn; force 0 tells the others the trial is over
            action.force_direction, action.force_n = 0, 0.0
            action.winning_neuron = action.winning_segment = 0
        else:
            neuron, segment = self.agent.act(np.frombuffer(spikes.spikes, dtype=np.uint8))
            action.force_direction = 1 if neuron else -1
            action.force_n = self.params.force if neuron else -self.params.force
            action.winning_neuron, action.winning_segment = neuron, segment
        self.action_pub.publish(self.stamp(action, reward.tick, reward.trial))
        if reward.trial_over:
            w = self.agent.weights
            self.weights_pub.publish(self.stamp(WeightSnapshot(
                neurons=w.shape[0], segments=w.shape[1], inputs=w.shape[2],
                weights=w.ravel().tolist()), reward.tick, reward.trial))


def main() -> None:
    raise SystemExit(node_main(AgentNode))


if __name__ == "__main__":
    main()
