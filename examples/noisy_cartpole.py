"""A cart-pole with friction and a noisy actuator, written only against docs/ENV_CONTRACT.md
(contract version 4: rclpy and the message packages, no clnn_ros code).
    python -m clnn_ros.run_all --env-node "python examples/noisy_cartpole.py"
    python -m clnn_ros.live.check_env python examples/noisy_cartpole.py --ros-args \\
        -p force_noise:=0.2
Its own parameters (-p on its command line): cart_friction, pole_friction, force_noise.
Topic names are relative: `--ros-args -r __ns:=/robot1 -r /clock:=/robot1/clock` moves it.
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
POLE_ANGLE, CART_POSITION = 1, 2  # Observation.termination: 1 + index of termination_reasons
DEFAULTS = dict(tau=0.02, max_steps=10000, angle_limit_deg=12.0, track_limit_m=2.4, gravity=9.8,
                cart_mass=0.711, pole_mass=0.209, pole_length=0.326, force=10.0,  # contract's
                cart_friction=0.0005, pole_friction=2e-6, force_noise=0.1, noise_seed=0)  # own


class NoisyCartPole(Node):
    def __init__(self):
        super().__init__("environment", automatically_declare_parameters_from_overrides=True)
        self.set_parameters([rclpy.Parameter("use_sim_time", value=True)])  # ROS time = tick * tau
        self.p = {k: self.get_parameter_or(k, rclpy.Parameter(k, value=v)).value
                  for k, v in DEFAULTS.items()}
        self.rng, self.tau_ns = random.Random(self.p["noise_seed"]), round(self.p["tau"] * 1e9)
        self.tick, self.trial, self.steps, self.over, self.done = 0, 0, 0, True, False
        self.over_tick = None  # the tick of a trial's last observation, which ACTION_NONE answers
        self.pending, self.s = {}, [0.0, 0.0, 0.0, 0.0]  # x m, dx/dt m/s, theta rad, rad/s
        inf, a, x = math.inf, self.p["angle_limit_deg"], self.p["track_limit_m"]
        self.create_publisher(TaskDescription, "env/task", LATCHED).publish(TaskDescription(
            contract_version=4, task="cartpole", variable_names=[
                "cart_position", "cart_velocity", "pole_angle", "pole_angular_velocity"],
            variable_units=["m", "m/s", "deg", "deg/s"], variable_low=[-x, -inf, -a, -inf],
            variable_high=[x, inf, a, inf], action_labels=["-F", "+F"], action_values=[-1.0, 1.0],
            max_steps=self.p["max_steps"], reward_threshold=math.nan, ends_in="failure",
            termination_reasons=["pole_angle", "cart_position"]))
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
            ok = self.over and abs(e.initial_angle_deg) < self.p["angle_limit_deg"]
            if ok and e.tick == self.tick:
                self.offer("start", e)
            else:
                self.refuse(f"START of tick {e.tick}, angle {e.initial_angle_deg}")

    def on_action(self, a):  # 0: -F, 1: +F; ACTION_NONE answers a trial's last observation
        if a.action == Action.ACTION_NONE and a.tick == self.over_tick:
            self.over_tick = None
        elif a.action not in (0, 1) or a.tick + 1 != self.tick or self.over:
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
        termination = 0
        if start:
            self.trial, self.steps = start.trial, 0
            self.s = [0.0, 0.0, math.radians(start.initial_angle_deg), 0.0]
        else:
            noise = 1 + self.p["force_noise"] * self.rng.gauss(0, 1)
            termination = self.physics((2 * action.action - 1) * self.p["force"] * noise)
            self.steps += not termination
        truncated = not termination and self.steps >= self.p["max_steps"]
        self.over = bool(termination) or truncated
        if self.over:  # its ACTION_NONE may come after the next START: matched by its tick
            self.over_tick = self.tick
        x, xd, th, thd = self.s
        self.pub.publish(Observation(
            tick=self.tick, trial=self.trial, values=[x, xd, math.degrees(th), math.degrees(thd)],
            reward=0.0, terminated=bool(termination), truncated=truncated,
            termination=termination, successful_steps=self.steps))
        self.tick += 1

    def physics(self, f):  # Barto et al. (1983) with cart and pole friction, semi-implicit Euler
        p, (x, xd, th, thd) = self.p, self.s
        m, l, mt = p["pole_mass"], p["pole_length"], p["cart_mass"] + p["pole_mass"]
        sin, cos = math.sin(th), math.cos(th)
        tmp = (f + m * l * thd * thd * sin - p["cart_friction"] * math.copysign(1, xd)) / mt
        tha = (p["gravity"] * sin - cos * tmp - p["pole_friction"] * thd / (m * l)) / (
            l * (4 / 3 - m * cos * cos / mt))
        xd += p["tau"] * (tmp - m * l * tha * cos / mt)
        thd += p["tau"] * tha
        self.s = [x + p["tau"] * xd, xd, th + p["tau"] * thd, thd]
        if abs(math.degrees(self.s[2])) > p["angle_limit_deg"]:
            return POLE_ANGLE
        return CART_POSITION if abs(self.s[0]) > p["track_limit_m"] else 0


def stop_at_end_of_stdin(node):  # run_all never writes to our stdin: end of file = it is gone
    while os.read(0, 4096):  # the raw fd (a daemon thread inside sys.stdin blocks the exit)
        pass
    node.done = True


rclpy.init()
node = NoisyCartPole()
if os.environ.get("CLNN_ROS_EXIT_WITH_STDIN") == "1":
    threading.Thread(target=stop_at_end_of_stdin, args=(node,), daemon=True).start()
try:
    while rclpy.ok() and not node.done:
        rclpy.spin_once(node, timeout_sec=0.1)
except (KeyboardInterrupt, ExternalShutdownException):  # SIGINT, SIGTERM: a quiet exit
    pass
node.destroy_node()
rclpy.try_shutdown()
