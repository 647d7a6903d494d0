"""A task of its own, no cart-pole: a point on a track from -1 m to 1 m must come to rest at a
goal. Written only against docs/ENV_CONTRACT.md (contract version 4: rclpy and the message
packages, no clnn_ros code).
    python -m clnn_ros.live.check_env --option task=point_to_goal --option n_actions=3 \\
        python examples/point_to_goal.py
    python -m clnn_ros.run_all --env-node "python examples/point_to_goal.py" \\
        --option task=point_to_goal --option n_actions=3 --option state_vars=offset,velocity \\
        --option variable_edges='offset:-0.5,-0.1,0.1,0.5;velocity:-0.2,0.2' \\
        --option reward_mapping=goal --option sigma=128 --option omega=128 --max-steps 300
Actions: push left, coast, push right (2 m/s^2 against a drag of 1/s; the track's ends stop the
point). Observation: the goal's offset from the point (m) and the point's velocity (m/s). The
trial terminates, a success, when the point is within 0.1 m of the goal and slower than 0.3 m/s;
each trial's start and goal are drawn from the START's seed and trial. Reward: -1 a step.
"""
import math, os, random, threading
import rclpy
from rclpy.clock import Clock as RosClock, ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String
from clnn_ros_msgs.msg import Action, Observation, TaskDescription, TrialEvent

LOCKSTEP = QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE)  # KEEP_LAST, VOLATILE
READY = QoSProfile(depth=16, reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.TRANSIENT_LOCAL)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
PUSH = [-2.0, 0.0, 2.0]  # m/s^2 of each action: left, coast, right
DRAG, GOAL_M, REST_M_PER_S = 1.0, 0.1, 0.3
TASK = TaskDescription(
    contract_version=4, task="point_to_goal", variable_names=["offset", "velocity"],
    variable_units=["m", "m/s"], variable_low=[-2.0, -2.0], variable_high=[2.0, 2.0],
    action_labels=["left", "coast", "right"], action_values=PUSH, max_steps=0,
    reward_threshold=math.nan, ends_in="success", termination_reasons=["at_goal"])


class PointToGoal(Node):
    def __init__(self):
        super().__init__("environment", automatically_declare_parameters_from_overrides=True)
        self.set_parameters([rclpy.Parameter("use_sim_time", value=True)])  # ROS time = tick * tau
        self.p = {k: self.get_parameter_or(k, rclpy.Parameter(k, value=v)).value
                  for k, v in dict(tau=0.02, max_steps=10000).items()}
        self.tau_ns = round(self.p["tau"] * 1e9)
        self.tick, self.trial, self.steps, self.over, self.done = 0, 0, 0, True, False
        self.over_tick = None  # the tick of a trial's last observation, which ACTION_NONE answers
        self.pending, self.x, self.v, self.goal = {}, 0.0, 0.0, 0.0
        self.create_publisher(TaskDescription, "env/task", LATCHED).publish(TASK)
        self.pub = self.create_publisher(Observation, "env/observation", LOCKSTEP)
        self.ready = self.create_publisher(String, "_graph/ready", READY)
        # sim time stands still before the first tick: the readiness timer runs on steady time
        self.timer = self.create_timer(0.02, self.announce, clock=RosClock(
            clock_type=ClockType.STEADY_TIME))
        self.inputs = [self.create_subscription(Clock, "clock", self.on_clock, LOCKSTEP),
                       self.create_subscription(TrialEvent, "trial/event", self.on_event, LOCKSTEP),
                       self.create_subscription(Action, "rln/action", self.on_action, LOCKSTEP)]

    def announce(self):  # encoder, reward and trial manager subscribe to observations; each input
        # must know its publisher too (discovery is one-sided: an unmatched reader drops data)
        if self.pub.get_subscription_count() >= 3 and all(
                s.get_publisher_count() for s in self.inputs):
            self.ready.publish(String(data="environment")), self.timer.cancel()

    def refuse(self, why):
        self.get_logger().error(f"refused at tick {self.tick}: {why}")

    def on_clock(self, m):
        ns = m.clock.sec * 10**9 + m.clock.nanosec
        if ns == self.tick * self.tau_ns:
            self.offer("clock", m)
        else:
            self.refuse(f"clock {ns} ns")

    def on_event(self, e):
        if e.event == TrialEvent.EPISODE_END:
            self.done = True
        elif e.event == TrialEvent.START:
            if self.over and e.tick == self.tick:
                self.offer("start", e)
            else:
                self.refuse(f"START of tick {e.tick}")

    def on_action(self, a):  # an index of PUSH; ACTION_NONE answers a trial's last observation
        if a.action == Action.ACTION_NONE and a.tick == self.over_tick:
            self.over_tick = None
        elif a.action >= len(PUSH) or a.tick + 1 != self.tick or self.over:
            self.refuse(f"action {a.action} of tick {a.tick}")
        else:
            self.offer("action", a)

    def offer(self, key, msg):
        if key in self.pending:
            return self.refuse(f"a second {key}")
        self.pending[key] = msg
        if "clock" in self.pending and len(self.pending) == 2:  # clock + (START or action)
            start, action, self.pending = self.pending.get("start"), self.pending.get("action"), {}
            self.advance(start, action)

    def advance(self, start, action):
        reward, at_goal = 0.0, False
        if start:  # start and goal at least 0.5 m apart, drawn from the seed and the trial
            self.trial, self.steps, self.v = start.trial, 0, 0.0
            rng, self.x, self.goal = random.Random(start.seed * 1_000_003 + start.trial), 0, 0
            while abs(self.goal - self.x) < 0.5:
                self.x, self.goal = rng.uniform(-1, 1), rng.uniform(-1, 1)
        else:
            tau = self.p["tau"]
            self.v += tau * (PUSH[action.action] - DRAG * self.v)
            self.x += tau * self.v
            if abs(self.x) > 1.0:  # the end of the track stops the point
                self.x, self.v = math.copysign(1.0, self.x), 0.0
            at_goal = abs(self.goal - self.x) < GOAL_M and abs(self.v) < REST_M_PER_S
            reward, self.steps = -1.0, self.steps + (not at_goal)
        truncated = not at_goal and self.steps >= self.p["max_steps"]
        self.over = at_goal or truncated
        if self.over:  # its ACTION_NONE may come after the next START: matched by its tick
            self.over_tick = self.tick
        self.pub.publish(Observation(
            tick=self.tick, trial=self.trial, values=[self.goal - self.x, self.v], reward=reward,
            terminated=at_goal, truncated=truncated, termination=int(at_goal),
            successful_steps=self.steps))
        self.tick += 1


def stop_at_end_of_stdin(node):  # run_all never writes to our stdin: end of file = it is gone
    while os.read(0, 4096):  # the raw fd (a daemon thread inside sys.stdin blocks the exit)
        pass
    node.done = True


rclpy.init()
node = PointToGoal()
if os.environ.get("CLNN_ROS_EXIT_WITH_STDIN") == "1":
    threading.Thread(target=stop_at_end_of_stdin, args=(node,), daemon=True).start()
try:
    while rclpy.ok() and not node.done:
        rclpy.spin_once(node, timeout_sec=0.1)
except (KeyboardInterrupt, ExternalShutdownException):  # SIGINT, SIGTERM: a quiet exit
    pass
node.destroy_node()
rclpy.try_shutdown()
