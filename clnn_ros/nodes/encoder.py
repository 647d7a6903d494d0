"""Encoder node: observation -> spike vector (Table 1's intervals, for any task's variables).

    python -m clnn_ros.nodes.encoder --ros-args -p nsv:=2 -p velocity_edge:=0.5

Reads the environment's task once (env/task, latched: the names, units and bounds of its
variables), then encodes every env/observation(t) into rln/spikes(t), the 1-hot code of each
encoded variable, and publishes once, latched, rln/input_labels: what each input means. A task
that does not fit the run, or an observation that does not fit the task, is refused. Ends on
trial/event EPISODE_END.
"""

from __future__ import annotations

from clnn_ros_msgs.msg import InputLabels, Observation, SpikeVector, TaskDescription, TrialEvent
from rclpy.node import Node
from rclpy.task import Future

from ..core.encoder import Encoder
from ..graph.lockstep import Refusals, TickJoin
from ..graph.names import INPUT_LABELS, SPIKES, STATE, TASK, TRIAL_EVENT
from ..graph.task_description import described, description_problem
from .glue import (LABELS_QOS, LOCKSTEP_QOS, Readiness, checked, declare_run_parameters,
                   endpoints_matched, ends_with_the_episode, run_node, use_sim_time)


class EncoderNode(Node):
    def __init__(self, run: dict, **node_options):
        super().__init__("encoder", **node_options)
        self.params, settings = declare_run_parameters(self, "encoder", run)
        use_sim_time(self, "encoder")
        self.task = self.encoder = None  # the environment's, once its description is in
        self.finished, self.failure = Future(), None
        self.refusals = Refusals(self.get_logger().error)
        self.join = TickJoin((STATE,), self.on_tick, self.refusals)
        self.spikes_msg = SpikeVector()  # one message object, refilled each tick
        self.spikes_pub = self.create_publisher(SpikeVector, SPIKES, LOCKSTEP_QOS)
        self.labels_pub = self.create_publisher(InputLabels, INPUT_LABELS, LABELS_QOS)
        self.create_subscription(TaskDescription, TASK, self.on_task, LABELS_QOS)
        state_sub = self.create_subscription(
            Observation, STATE,
            checked(STATE, self.params, self.refusals, self.on_observation), LOCKSTEP_QOS)
        self.create_subscription(TrialEvent, TRIAL_EVENT, checked(
            TRIAL_EVENT, self.params, self.refusals,
            ends_with_the_episode(self.finished, self.refusals, self.join.standing,
                                  self.get_logger().warning)),
            LOCKSTEP_QOS)
        # spikes go to the agent and the trial manager
        matched = endpoints_matched(settings["extra_nodes"], [(self.spikes_pub, 2)], [state_sub])
        self.readiness = Readiness(self, lambda: self.encoder is not None and matched(),
                                   is_running=lambda: self.join.tick > 0)

    def on_task(self, msg: TaskDescription) -> None:
        if self.task is not None:
            return  # the same latched description again (a second publisher is the graph's)
        if problem := description_problem(msg, self.params):
            self.refusals.refuse(TASK, msg, problem, kind="content")
            return
        self.task = described(msg)
        self.encoder = Encoder.from_params(self.params, self.task.task.names,
                                           self.task.task.units)
        self.labels_pub.publish(InputLabels(labels=self.encoder.labels()))

    def on_observation(self, msg: Observation) -> None:
        if self.task is None:
            self.refusals.refuse(STATE, msg, "no task description (env/task) came first")
        elif problem := self.task.observation_problem(msg.values):
            self.refusals.refuse(STATE, msg, problem, kind="content")
        else:
            self.join.offer(STATE, msg)

    def on_tick(self, inbox: dict) -> None:
        msg = inbox[STATE]
        spikes = self.encoder.spikes(msg.values)
        out = self.spikes_msg
        out.tick, out.trial, out.spikes = msg.tick, msg.trial, spikes.tobytes()
        self.spikes_pub.publish(out)


def main() -> None:
    raise SystemExit(run_node(EncoderNode))


if __name__ == "__main__":
    main()
