"""Reward node: the success counter. Each observation's outcome becomes the rule's 1-hot
reward R by the run's reward_mapping: the paper's ("failure"), [0,1] punishment when the step
terminated, [1,0] a positive reward every sigma successful steps, [0,0] otherwise; "goal" (a task
that terminates at its goal), a reward when it terminates, a punishment every omega steps
without it; "shaped" (a task whose rewards say how well it goes), the sign of the observations'
rewards summed since the last signal, every sigma steps and when a step terminates. It also
tells the agent when the trial is over (terminated or truncated).

    python -m clnn_ros.nodes.reward --ros-args -p sigma:=256

Subscribes env/observation(t); publishes rln/reward(t). Ends on trial/event EPISODE_END.
"""

from __future__ import annotations

from clnn_ros_msgs.msg import Observation, Reward, TrialEvent
from rclpy.node import Node
from rclpy.task import Future

from ..core.rln import NONE, ONE_HOT
from ..graph.lockstep import Refusals, TickJoin
from ..graph.names import REWARD, STATE, TRIAL_EVENT
from ..graph.run import NODE_PARAMETERS
from ..core.init_weights import episode_start
from .glue import (LOCKSTEP_QOS, Readiness, checked, declare_run_parameters,
                   endpoints_matched, ends_with_the_episode, run_node, use_sim_time)


class RewardNode(Node):
    def __init__(self, run: dict, **node_options):
        super().__init__("reward", **node_options)
        self.params, settings = declare_run_parameters(self, "reward", run)
        use_sim_time(self, "reward")
        # a resumed episode (init_weights: a checkpoint) continues a carried success count
        self.counter = episode_start(settings["init_weights"], settings["seed"], self.params,
                                     NODE_PARAMETERS["reward"]).success_counter(self.params)
        self.trial = -1
        self.finished, self.failure = Future(), None
        self.refusals = Refusals(self.get_logger().error)
        self.join = TickJoin((STATE,), self.on_tick, self.refusals)
        self.reward_msg = Reward()  # one message object, refilled each tick
        self.reward_pub = self.create_publisher(Reward, REWARD, LOCKSTEP_QOS)
        state_sub = self.create_subscription(
            Observation, STATE,
            checked(STATE, self.params, self.refusals, lambda msg: self.join.offer(STATE, msg)),
            LOCKSTEP_QOS)
        self.create_subscription(TrialEvent, TRIAL_EVENT, checked(
            TRIAL_EVENT, self.params, self.refusals,
            ends_with_the_episode(self.finished, self.refusals, self.join.standing,
                                  self.get_logger().warning)),
            LOCKSTEP_QOS)
        # rewards go to the agent and the trial manager
        self.readiness = Readiness(self, endpoints_matched(
            settings["extra_nodes"], [(self.reward_pub, 2)], [state_sub]),
            is_running=lambda: self.join.tick > 0)

    def on_tick(self, inbox: dict) -> None:
        msg = inbox[STATE]
        if msg.trial != self.trial:  # the trial's first state: no step has been taken yet
            self.trial = msg.trial
            self.counter.begin_trial()
            kind = NONE
        else:
            kind = self.counter.outcome(msg.terminated, msg.reward)
        out = self.reward_msg
        out.tick, out.trial, out.reward_one_hot = msg.tick, msg.trial, ONE_HOT[kind]
        out.success_counter = self.counter.count
        out.trial_over = msg.terminated or msg.truncated
        self.reward_pub.publish(out)


def main() -> None:
    raise SystemExit(run_node(RewardNode))


if __name__ == "__main__":
    main()
