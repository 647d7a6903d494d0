"""Agent node: one RLN per action of the task (n_actions; the cart-pole's two). Spike vector + reward of a tick -> three-factor update, inference,
tagging -> action. At the end of each trial it saves its checkpoint (<out_dir>/checkpoint.npz:
the state the episode resumes from) and publishes its weights. The service
~/save_checkpoint (std_srvs/Trigger; /agent/save_checkpoint in the root namespace) saves the state after the last completed tick to
<out_dir>/checkpoint_<tick>.npz and answers with the path.

    python -m clnn_ros.nodes.agent --ros-args -p seed:=1 -p nsv:=1

Subscribes rln/spikes(t) and rln/reward(t); publishes rln/action(t), and rln/weights after each
trial. Ends on trial/event EPISODE_END.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from clnn_ros_msgs.msg import Action, Reward, SpikeVector, TrialEvent, WeightSnapshot
from rclpy.node import Node
from rclpy.task import Future
from std_srvs.srv import Trigger

from ..core.checkpoint import capture, save_checkpoint
from ..core.episode import start_episode
from ..core.rln import KIND_OF_CODE
from ..graph.fields import ACTION_NONE
from ..files import describe_write_error
from ..core.init_weights import episode_start
from ..graph.lockstep import Refusals, TickJoin
from ..graph.names import ACTION, REWARD, SAVE_CHECKPOINT, SPIKES, TRIAL_EVENT, WEIGHTS
from ..graph.run import NODE_PARAMETERS
from .glue import (LOCKSTEP_QOS, Readiness, checked, declare_run_parameters,
                   endpoints_matched, ends_with_the_episode, run_node, use_sim_time)


class AgentNode(Node):
    def __init__(self, run: dict, **node_options):
        super().__init__("agent", **node_options)
        self.params, self.settings = declare_run_parameters(self, "agent", run)
        use_sim_time(self, "agent")
        # the seed's weights, or those of init_weights (a checkpoint: its whole state)
        start = episode_start(self.settings["init_weights"], self.settings["seed"], self.params,
                              NODE_PARAMETERS["agent"])
        self.agent, self.counter, self.next_trial = start_episode(
            self.settings["seed"], self.params, start.weights, start.resume)
        self.trial = -1
        self.trial_start_tick = self.last_tick = None
        self.trial_step = 0  # ticks of trial next_trial done: 0 between two trials
        self.finished, self.failure = Future(), None
        self.refusals = Refusals(self.get_logger().error)
        self.join = TickJoin((SPIKES, REWARD), self.on_tick, self.refusals)
        self.action_msg = Action()  # one message object, refilled each tick
        self.action_pub = self.create_publisher(Action, ACTION, LOCKSTEP_QOS)
        self.weights_pub = self.create_publisher(WeightSnapshot, WEIGHTS, LOCKSTEP_QOS)
        inputs = [self.create_subscription(
            msg_type, topic,
            checked(topic, self.params, self.refusals,
                    lambda msg, topic=topic: self.join.offer(topic, msg)), LOCKSTEP_QOS)
            for msg_type, topic in ((SpikeVector, SPIKES), (Reward, REWARD))]
        self.create_subscription(TrialEvent, TRIAL_EVENT, checked(
            TRIAL_EVENT, self.params, self.refusals,
            ends_with_the_episode(self.finished, self.refusals, self.join.standing,
                                  self.get_logger().warning)),
            LOCKSTEP_QOS)
        self.create_service(Trigger, SAVE_CHECKPOINT, self.on_save_checkpoint)
        # actions go to the environment and the trial manager, weights to the trial manager
        self.readiness = Readiness(self, endpoints_matched(
            self.settings["extra_nodes"], [(self.action_pub, 2), (self.weights_pub, 1)], inputs),
            is_running=lambda: self.join.tick > 0)

    def on_tick(self, inbox: dict) -> None:
        spikes, reward = inbox[SPIKES], inbox[REWARD]
        if reward.trial != self.trial:  # a trial's first tick: counters restart, nothing to learn
            self.trial, self.trial_start_tick = reward.trial, reward.tick
            self.agent.begin_trial(reward.trial)
        else:
            self.agent.learn(KIND_OF_CODE[tuple(reward.reward_one_hot.tolist())])
        self.counter.count = reward.success_counter  # the reward node's count, for checkpoints
        self.last_tick = reward.tick
        self.next_trial = reward.trial + 1 if reward.trial_over else reward.trial
        self.trial_step = 0 if reward.trial_over else reward.tick - self.trial_start_tick + 1
        action = self.action_msg
        if reward.trial_over:  # only learn; ACTION_NONE tells the others the trial is over
            action.action, action.winning_segment = ACTION_NONE, 0
        else:
            action.action, action.winning_segment = self.agent.act(
                np.frombuffer(spikes.spikes, dtype=np.uint8))
        action.tick, action.trial = reward.tick, reward.trial
        self.action_pub.publish(action)
        if reward.trial_over:
            try:
                self.save("checkpoint.npz")  # before the weights: on disk when the episode ends
            except OSError as error:  # the run ends with one line naming the cause
                self.failure = describe_write_error(error)
                self.get_logger().error(self.failure)
                self.finished.set_result(1)
                return
            w = self.agent.weights
            self.weights_pub.publish(WeightSnapshot(
                tick=reward.tick, trial=reward.trial, neurons=w.shape[0], segments=w.shape[1],
                inputs=w.shape[2], weights=w.ravel().tolist()))

    def save(self, name: str) -> Path | None:
        """Save the state after the last completed tick to <out_dir>/name; None without an
        out_dir."""
        if not self.settings["out_dir"]:
            return None
        out = Path(self.settings["out_dir"])
        out.mkdir(parents=True, exist_ok=True)
        return save_checkpoint(out / name, capture(
            self.agent, self.counter, self.settings["seed"], self.next_trial, self.trial_step,
            self.last_tick))

    def on_save_checkpoint(self, _request, response):
        """Service callbacks run between two ticks' callbacks: the state after a whole tick."""
        if self.last_tick is None:
            response.success, response.message = False, "no tick has completed yet"
            return response
        try:
            path = self.save(f"checkpoint_{self.last_tick}.npz")
        except OSError as error:
            path, response.message = None, describe_write_error(error)
        else:
            response.message = str(path) if path else "no out_dir set: nowhere to save"
        response.success = path is not None
        return response


def main() -> None:
    raise SystemExit(run_node(AgentNode))


if __name__ == "__main__":
    main()
