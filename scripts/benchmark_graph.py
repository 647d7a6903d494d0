"""Benchmark of the ROS 2 node graph against a raw DDS lockstep ring of the same shape, all
measured in this one run: throughput as ratios, per-tick latency, a 50 Hz run paced by the
environment (as a robot runs it), idle and under CPU hogs, and a profile of the graph.

    ROS_DOMAIN_ID=N python scripts/benchmark_graph.py [--out docs/benchmark_graph.md] [--quick]

About 5 minutes (--quick: about 1.5 minutes, one run of each with fewer ticks, a smoke test;
it prints the report and writes it only with --out). The ROS domain is the environment's
ROS_DOMAIN_ID (ROS's default 0 when unset; give the benchmark a domain of its own), DDS discovery
stays on loopback (clnn_ros.rosenv's defaults apply to every process started here: the graph's,
the ring's, the benchmark's own).

1. Throughput (ticks/s): the graph, `python -m clnn_ros.run_all --quiet --no-record --seed 1
   --trials N` in 5 processes and composed in one (ticks_per_s from its summary.json: first tick
   to last), against the raw ring: 5 nodes (trial_manager, environment, encoder, reward, agent)
   that exchange exactly the lockstep messages of a tick and do nothing else:
        trial_manager --clock--> environment
        environment   --state--> encoder, reward, trial_manager
        encoder       --spikes--> agent, trial_manager
        reward        --reward--> agent, trial_manager
        agent         --action--> environment (for the next tick), trial_manager
   i.e. 5 publications and 10 deliveries per tick, 4 hops on the critical path; each node
   publishes once it holds its inputs of the tick, as the graph's nodes do. std_msgs/UInt64
   messages (the transport yardstick) and the graph's own message types with fixed content.
   The ring runs under the same rosenv defaults (its Fast DDS profile file), with the graph's
   QoS object (clnn_ros.nodes.common.LOCKSTEP_QOS, from clnn_ros.graph.qos.LOCKSTEP; the report
   states its depth) and the graph's executor
   factory (clnn_ros.nodes.common.make_executor, CLNN_ROS_EXECUTOR). EventsExecutor (the
   default) and rclpy's SingleThreadedExecutor (CLNN_ROS_EXECUTOR=single). Every configuration
   runs REPEATS times, round robin; the best (highest) rate counts, the least disturbed by other
   load on the machine, with the range of all runs.
2. Per-tick latency of the graph, from the same graph runs: in the trial manager, the wall
   time from publishing clock(t) to holding state(t) and action(t) (one tick's whole round trip
   through the graph), timed by a hook that this script puts into the run through a temporary
   sitecustomize.py (run_all runs unchanged): it wraps the trial manager's clock publisher and
   its TickJoin's completion (clnn_ros.nodes.common.TickJoin). p50, p99, max.
3. 50 Hz paced by the environment: `run_all --env-node "python <this script> paced-env ..."`
   (the recorder on, as run_all runs by default); the environment node (EnvironmentNode, with
   its state publication paced) publishes state(t) at the first slot of a 20 ms wall-clock grid
   after its inputs are in; for every tick, the time from publishing state(t) to receiving the
   agent's action(t) in the environment node: the share within 20 ms, p50, p99, max; idle, and
   with 2 x cores (at least 4) busy `python` processes, killed afterwards (and each ends by
   itself after a time limit in any case).

Profiles (EventsExecutor): the composed graph under cProfile from the trial manager's first
clock to its stop (a driver that wraps TrialManagerNode.publish_clock and .stop), and one
5-process run with every node process under cProfile with a CPU-time timer from its first
publication (GraphNode.stamp) to its exit (the sitecustomize hook). A hook point that no longer
exists fails the benchmark: nothing falls back silently to another measurement.
Exclusive time is grouped into the executor, rclpy's TimeSource (/clock for use_sim_time),
publish, received message objects, message construction, node callbacks, numpy, the core model
and other; plus a micro-benchmark of serialization alone.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import pstats
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from clnn_ros import qos

REPO = Path(__file__).resolve().parents[1]
SEED = 1
# Seed 1, 1 SV: a trial is about 270 ticks; 30 trials = 8402 ticks, 8 = 1912, 6 = 1381,
# 5 = 1115, 2 = 302.
FULL = dict(repeats=3, graph_trials={"events": 30, "single": 5},
            ring_ticks={("separate", "events"): 5000, ("composed", "events"): 20000,
                        ("separate", "single"): 1000, ("composed", "single"): 1000},
            profile_trials=8, paced_trials=6)
QUICK = dict(repeats=1, graph_trials={"events": 8, "single": 2},
             ring_ticks={("separate", "events"): 1000, ("composed", "events"): 4000,
                         ("separate", "single"): 500, ("composed", "single"): 500},
             profile_trials=2, paced_trials=2)
RUN_TIMEOUT_S = 120
TEARDOWN_GRACE_S = 10.0  # a ring process still running this long after the result is killed
LAYOUTS = ("separate", "composed")
EXECUTORS = ("events", "single")
EXECUTOR_NAMES = {"events": "EventsExecutor", "single": "SingleThreadedExecutor"}
LAYOUT_NAMES = {"separate": "5 processes", "composed": "composed (1 process)"}
# The graph / raw UInt64 ring targets (EventsExecutor): at least, and the aim.
TARGETS = {"separate": 0.60, "composed": 0.40}
AIM = 0.70
# The 50 Hz run: the environment's period, the deadline of the agent's answer, the hogs.
PERIOD_MS = 20.0
DEADLINE_MS = 20.0
PACED_TIMEOUT_S = 180
HOGS = max(4, 2 * (os.cpu_count() or 1))
# A busy process that ends by itself after argv[1] seconds, should the benchmark be killed.
HOG = ("import sys, time\nend = time.monotonic() + float(sys.argv[1])\n"
       "while time.monotonic() < end:\n    for _ in range(100000):\n        pass\n")

ROLES = ("environment", "encoder", "reward", "agent", "trial_manager")
# topic: (publishing role, subscribing roles); the graph's clock, cartpole/state, rln/spikes,
# rln/reward and rln/action
EDGES = {
    "clock": ("trial_manager", ("environment",)),
    "state": ("environment", ("encoder", "reward", "trial_manager")),
    "spikes": ("encoder", ("agent", "trial_manager")),
    "reward": ("reward", ("agent", "trial_manager")),
    "action": ("agent", ("environment", "trial_manager")),
}
# A role publishes its message number k once it holds message k - lag of each listed topic:
# the environment needs clock(t) and action(t-1); the trial manager publishes clock(t+1) after
# state(t) and action(t) (its clock(0) is the start).
NEEDS = {
    "environment": (("clock", 0), ("action", 1)),
    "encoder": (("state", 0),),
    "reward": (("state", 0),),
    "agent": (("spikes", 0), ("reward", 0)),
    "trial_manager": (("state", 1), ("action", 1)),
}
RING_NS = "/bench_ring"
# The graph's nodes with use_sim_time, whose rclpy TimeSource subscribes /clock as well.
TIME_SOURCES = 4
TYPE_NAMES = {"clock": "rosgraph_msgs/Clock", "state": "clnn_ros_msgs/CartPoleState",
              "spikes": "clnn_ros_msgs/SpikeVector", "reward": "clnn_ros_msgs/Reward",
              "action": "clnn_ros_msgs/Action"}


def type_name(topic: str) -> str:
    return TYPE_NAMES[topic]


# ----------------------------------------------------------------------------- raw ring nodes

def ring_messages(kind: str) -> dict:
    """One reusable message per topic: std_msgs/UInt64, or the graph's types with the content
    of a typical tick (fixed: no model work)."""
    if kind == "uint64":
        from std_msgs.msg import UInt64
        return {topic: UInt64() for topic in EDGES}
    from clnn_ros_msgs.msg import Action, CartPoleState, Reward, SpikeVector
    from rosgraph_msgs.msg import Clock

    labels = ["pole_angle[-12,-6)deg", "pole_angle[-6,-1)deg", "pole_angle[-1,0)deg",
              "pole_angle[0,1)deg", "pole_angle[1,6)deg", "pole_angle[6,12]deg"]
    return {
        "clock": Clock(),
        "state": CartPoleState(cart_position_m=0.01, cart_velocity_m_per_s=0.1,
                               pole_angle_deg=-0.5, pole_angular_velocity_deg_per_s=3.0,
                               successful_steps=100),
        "spikes": SpikeVector(spikes=[0, 0, 1, 0, 0, 0], input_labels=labels,
                              spiking_inputs=[2]),
        "reward": Reward(reward_one_hot=[0, 0], kind="none", success_counter=100),
        "action": Action(force_direction=1, force_n=10.0, winning_neuron=1, winning_segment=3),
    }


def ring_node(role: str, kind: str, ticks: int, context=None):
    import rclpy.node
    from rclpy.task import Future

    from clnn_ros.nodes.common import LOCKSTEP_QOS as qos  # the graph's QoS, depth and all

    out_topic = next(t for t, (publisher, _) in EDGES.items() if publisher == role)
    in_topics = [t for t, (_, subscribers) in EDGES.items() if role in subscribers]
    messages = ring_messages(kind)

    class RingNode(rclpy.node.Node):
        def __init__(self):
            super().__init__(f"ring_{role}", context=context)
            self.msg = messages[out_topic]
            self.uint64 = kind == "uint64"
            self.is_clock = out_topic == "clock"
            self.pub = self.create_publisher(type(self.msg), f"{RING_NS}/{out_topic}", qos)
            self.expected_subscribers = len(EDGES[out_topic][1])
            self.counts = dict.fromkeys(in_topics, 0)
            self.needs = NEEDS[role]
            self.limit = ticks if role == "trial_manager" else None
            self.sent = 0
            self.finished = Future()
            self.started = self.ended = 0.0
            self.subs = [self.create_subscription(type(messages[t]), f"{RING_NS}/{t}",
                                                  self.receiver(t), qos) for t in in_topics]

        def matched(self) -> bool:
            return (self.pub.get_subscription_count() >= self.expected_subscribers
                    and all(s.get_publisher_count() >= 1 for s in self.subs))

        def receiver(self, topic):
            def receive(_msg):
                self.counts[topic] += 1
                self.advance()
            return receive

        def advance(self) -> None:
            counts, needs = self.counts, self.needs
            while all(counts[t] >= self.sent + 1 - lag for t, lag in needs):
                if self.limit is not None and self.sent >= self.limit:
                    self.ended = time.perf_counter()
                    if not self.finished.done():
                        self.finished.set_result(True)
                    return
                self.publish(self.sent)
                self.sent += 1

        def publish(self, k: int) -> None:
            msg = self.msg
            if self.uint64:
                msg.data = k
            elif self.is_clock:
                msg.clock.sec, msg.clock.nanosec = divmod(k * 20_000_000, 1_000_000_000)
            else:
                msg.tick = k
            self.pub.publish(msg)

        def start(self) -> None:
            self.started = time.perf_counter()
            self.advance()  # clock(0)

    return RingNode()


def spin_until(executor, done, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    return done()


def ring_result(tm, ticks: int) -> None:
    wall = tm.ended - tm.started
    print("RING_RESULT " + json.dumps({"ticks": ticks, "wall_s": wall,
                                       "ticks_per_s": ticks / wall}), flush=True)


def ring_composed(a) -> int:
    """All five ring nodes in one process, one executor."""
    import rclpy
    from clnn_ros.nodes.common import make_executor
    rclpy.init()
    nodes = {role: ring_node(role, a.msgs, a.ticks) for role in ROLES}
    executor = make_executor()
    for node in nodes.values():
        executor.add_node(node)
    tm = nodes["trial_manager"]
    if not spin_until(executor, lambda: all(n.matched() for n in nodes.values()), 30):
        print("ring: discovery timed out", file=sys.stderr)
        return 1
    tm.start()
    ok = spin_until(executor, tm.finished.done, RUN_TIMEOUT_S)
    if ok:
        ring_result(tm, a.ticks)
    executor.shutdown()
    for node in nodes.values():
        node.destroy_node()
    rclpy.shutdown()
    return 0 if ok else 1


def ring_stage(a) -> int:
    """One ring node in this process. Each node announces on a latched topic once its
    publisher and subscriptions have matched; the trial manager starts when all have, and
    ends the run with a latched stop message."""
    import rclpy
    from rclpy.duration import Duration
    from clnn_ros.nodes.common import READY_QOS, make_executor
    from std_msgs.msg import String

    rclpy.init()
    node = ring_node(a.role, a.msgs, a.ticks)
    executor = make_executor()
    executor.add_node(node)
    status = 0
    if a.role == "trial_manager":
        ready = set()
        node.create_subscription(String, f"{RING_NS}/ready", lambda m: ready.add(m.data),
                                 READY_QOS)
        stop = node.create_publisher(String, f"{RING_NS}/stop", READY_QOS)
        if not spin_until(executor, lambda: len(ready) == len(ROLES) - 1 and node.matched(), 30):
            print(f"ring: discovery timed out (ready: {sorted(ready)})", file=sys.stderr)
            status = 1
        else:
            node.start()
            if spin_until(executor, node.finished.done, RUN_TIMEOUT_S):
                ring_result(node, a.ticks)
            else:
                print(f"ring: stalled after {node.sent} ticks", file=sys.stderr)
                status = 1
        stop.publish(String(data="stop"))
        stop.wait_for_all_acked(Duration(seconds=2.0))
    else:
        stopped = []
        node.create_subscription(String, f"{RING_NS}/stop", stopped.append, READY_QOS)
        ready = node.create_publisher(String, f"{RING_NS}/ready", READY_QOS)
        announced = False
        deadline = time.monotonic() + RUN_TIMEOUT_S + 30
        while not stopped and time.monotonic() < deadline:
            if not announced and node.matched():
                ready.publish(String(data=a.role))
                announced = True
            executor.spin_once(timeout_sec=0.02 if not announced else 0.1)
        status = 0 if stopped else 1
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()
    return status


# ----------------------------------------------------------------------------- the paced environment

def paced_env(argv: list[str]) -> int:
    """The environment node of the 50 Hz run, as run_all --env-node starts it:
    `paced-env --out FILE [--period-ms 20] --ros-args ...`. The paper's cart-pole
    (EnvironmentNode), but each state goes out at the first slot of a wall-clock grid of
    `period` (anchored at state 0) after its inputs are in, as a robot's control loop
    publishes; the node waits for its slot inside the callback (it has nothing else to do). It
    notes when each state went out and when the agent's action of that tick came in, and writes
    them to FILE at the end: {"period_ns", "ticks": [[tick, slot, published_ns, answered_ns or
    null], ...]} (time.monotonic_ns, the same clock in every process)."""
    split = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    parser = argparse.ArgumentParser(prog="benchmark_graph.py paced-env")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--period-ms", type=float, default=PERIOD_MS)
    own = parser.parse_args(argv[:split])
    period_ns = round(own.period_ms * 1e6)

    from clnn_ros.nodes.common import node_main
    from clnn_ros.nodes.environment import EnvironmentNode

    class PacedEnvironmentNode(EnvironmentNode):
        def __init__(self, **options):
            super().__init__(**options)
            self.unpaced_pub, self.state_pub = self.state_pub, self  # _advance calls publish
            self.first_ns = None
            self.slot = -1
            self.published = {}  # tick: (slot, ns)
            self.answered = {}   # tick: ns, when the action of the tick came in

        def publish(self, state) -> None:
            now = time.monotonic_ns()
            if self.first_ns is None:
                self.first_ns, slot = now, 0
            else:  # the first slot not before now, after the last one used
                slot = max(self.slot + 1, -(-(now - self.first_ns) // period_ns))
                while (wait := self.first_ns + slot * period_ns - time.monotonic_ns()) > 0:
                    time.sleep(wait / 1e9)
            self.slot = slot
            self.published[state.tick] = (slot, time.monotonic_ns())
            self.unpaced_pub.publish(state)

        def on_action(self, action) -> None:
            self.answered.setdefault(action.tick, time.monotonic_ns())
            super().on_action(action)

    made = []
    status = node_main(lambda: made.append(PacedEnvironmentNode()) or made[-1],
                       [sys.argv[0], *argv[split:]])
    if made:
        node = made[0]
        own.out.parent.mkdir(parents=True, exist_ok=True)
        own.out.write_text(json.dumps({"period_ns": period_ns, "ticks": [
            [tick, slot, ns, node.answered.get(tick)]
            for tick, (slot, ns) in sorted(node.published.items())]}))
    return status


# ----------------------------------------------------------------------------- hooks

# Put on the PYTHONPATH of a run_all run (run_all and its nodes run unchanged), active where
# the variables are set:
# * CLNN_BENCH_TICKS_FILE: the trial manager (its own process, or composed in run_all's) notes
#   when it publishes each clock(t) and when its TickJoin holds state(t) and action(t), and
#   writes both lists to that file at exit. (Hooked through clnn_ros.nodes.common, which both
#   the module run as __main__ and the composed run share.)
# * CLNN_BENCH_PROFILE_DIR: each node process (python -m clnn_ros.nodes.NAME) runs under
#   cProfile with a CPU-time timer from its first publication (GraphNode.stamp) to its exit and
#   writes NAME.prof there.
SITECUSTOMIZE = r'''
import os
_TICKS = os.environ.get("CLNN_BENCH_TICKS_FILE")
_PROFILES = os.environ.get("CLNN_BENCH_PROFILE_DIR")
if _TICKS or _PROFILES:
    try:
        _cmd = open("/proc/self/cmdline", "rb").read().split(b"\0")
    except OSError:
        _cmd = []
    _module = next((c.decode() for c in _cmd if c.startswith(b"clnn_ros.")), "")
    if _module.startswith("clnn_ros.nodes.") or _module == "clnn_ros.run_all":
        import atexit, json, time
        from clnn_ros.nodes import common as _common
    if _TICKS and (_module == "clnn_ros.nodes.trial_manager" or _module == "clnn_ros.run_all"):
        _published, _completed = [], []
        _tickjoin_init = _common.TickJoin.__init__

        class _TimedPublisher:
            def __init__(self, publisher):
                self._publisher = publisher

            def publish(self, msg):
                _published.append(time.perf_counter_ns())
                self._publisher.publish(msg)

            def __getattr__(self, name):
                return getattr(self._publisher, name)

        def _init(self, node, topics, complete):
            if node.get_name() == "trial_manager":
                node.clock_pub = _TimedPublisher(node.clock_pub)
                untimed = complete

                def complete(inbox):
                    _completed.append(time.perf_counter_ns())
                    untimed(inbox)
            _tickjoin_init(self, node, topics, complete)

        _common.TickJoin.__init__ = _init

        def _write_ticks():
            if _published:
                with open(_TICKS, "w") as f:
                    json.dump({"published": _published, "completed": _completed}, f)
        atexit.register(_write_ticks)
    if _PROFILES and _module.startswith("clnn_ros.nodes."):
        import cProfile
        _profile = cProfile.Profile(time.thread_time)
        _stamp = _common.GraphNode.stamp
        _on = []

        def _profiled_stamp(self, *args, **kwargs):
            if not _on:
                _on.append(True)
                _profile.enable()
            return _stamp(self, *args, **kwargs)
        _common.GraphNode.stamp = _profiled_stamp

        def _dump():
            _profile.disable()
            if _on:
                _profile.dump_stats(os.path.join(_PROFILES, _module.rsplit(".", 1)[1] + ".prof"))
        atexit.register(_dump)
'''

# The composed run profiled from the trial manager's first clock (publish_clock(0)) to its
# stop(): the trial manager has these methods or the benchmark fails (no silent fallback).
COMPOSED_PROFILER = '''
import cProfile, sys
from clnn_ros import run_all
from clnn_ros.nodes import trial_manager
profile = cProfile.Profile()
TM = trial_manager.TrialManagerNode
missing = [m for m in ("publish_clock", "stop") if not hasattr(TM, m)]
if missing:
    raise SystemExit(f"TrialManagerNode has no {missing}: update COMPOSED_PROFILER")
publish_clock, stop = TM.publish_clock, TM.stop
def profiled_publish_clock(self, tick, *rest, **kw):
    if tick == 0:
        profile.enable()
    return publish_clock(self, tick, *rest, **kw)
def profiled_stop(self, *rest, **kw):
    profile.disable()
    return stop(self, *rest, **kw)
TM.publish_clock, TM.stop = profiled_publish_clock, profiled_stop
status = run_all.main(sys.argv[2:])
profile.dump_stats(sys.argv[1])
raise SystemExit(status)
'''


# ----------------------------------------------------------------------------- orchestration

def child_env(**extra) -> dict:
    env = dict(os.environ)
    env.update({k: str(v) for k, v in extra.items()})
    return env


def cpu_times() -> tuple[int, int]:
    """(busy, total) jiffies of the whole machine so far (/proc/stat)."""
    with open("/proc/stat") as stat:
        fields = [int(v) for v in stat.readline().split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    total = sum(fields[:8])  # guest time is counted in user already
    return total - idle, total


class CpuSampler:
    """Samples cpu_times() every `interval` s in a thread: how busy the whole machine was in a
    window of time.monotonic_ns()."""

    def __init__(self, interval: float = 0.25):
        import threading
        self.samples, self.interval = [], interval
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while True:
            self.samples.append((time.monotonic_ns(), *cpu_times()))
            if self.stopped.wait(self.interval):
                return

    def stop(self) -> None:
        self.stopped.set()
        self.thread.join()

    def busy_cores(self, start_ns: int, end_ns: int) -> float:
        """Average busy cores (every process) between the samples inside [start, end]."""
        inside = [s for s in self.samples if start_ns <= s[0] <= end_ns]
        if len(inside) < 2 or inside[-1][2] == inside[0][2]:
            return float("nan")
        (_, b0, t0), (_, b1, t1) = inside[0], inside[-1]
        return (os.cpu_count() or 1) * (b1 - b0) / (t1 - t0)


def kill_group(p: subprocess.Popen) -> None:
    if p.poll() is None:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def run_group(commands: list[list[str]], env: dict, timeout: float) -> list[str]:
    """Start the commands (each in its own process group), wait for all; on timeout (or an
    interruption of the benchmark) kill them all. Returns each one's stdout; raises on a
    failure."""
    procs = []
    try:
        for c in commands:
            procs.append(subprocess.Popen(c, cwd=REPO, env=env, stdin=subprocess.DEVNULL,
                                          stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                          text=True, start_new_session=True))
        deadline = time.monotonic() + timeout
        outputs, failed = [], []
        for p, c in zip(procs, commands):
            try:
                out, err = p.communicate(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                for q in procs:
                    kill_group(q)
                out, err = p.communicate()
                failed.append(f"{' '.join(c[-8:])}: timed out\n{err[-2000:]}")
                continue
            outputs.append(out)
            if p.returncode != 0:
                failed.append(f"{' '.join(c[-8:])}: exit {p.returncode}\n{err[-2000:]}")
    except BaseException:
        for q in procs:
            kill_group(q)
        raise
    if failed:
        raise RuntimeError("\n".join(failed))
    return outputs


class Bench:
    """The benchmark's settings and working directory."""

    def __init__(self, sizes: dict, work: Path):
        self.sizes, self.work = sizes, work
        self.forced_ring_exits = 0
        self.site = work / "site"
        self.site.mkdir()
        (self.site / "sitecustomize.py").write_text(SITECUSTOMIZE)
        self.pythonpath = os.pathsep.join(filter(None, [str(self.site),
                                                        os.environ.get("PYTHONPATH")]))

    def out_dir(self, name: str) -> Path:
        return self.work / f"{name}_{time.monotonic_ns()}"

    def graph_rate(self, layout: str, executor: str, trials: int, **env_extra) -> dict:
        """One run_all run without the recorder; its summary.json, with the per-tick latencies
        in microseconds ("latency_us") unless profiled."""
        out = self.out_dir(f"graph_{layout}_{executor}")
        ticks_file = out.with_name(out.name + "_ticks.json")
        cmd = [sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--no-record", "--trials",
               str(trials), "--seed", str(SEED), "--out", str(out)]
        if layout == "composed":
            cmd.append("--composed")
        env = child_env(CLNN_ROS_EXECUTOR=executor, PYTHONPATH=self.pythonpath, **env_extra)
        if "CLNN_BENCH_PROFILE_DIR" not in env_extra:
            env["CLNN_BENCH_TICKS_FILE"] = str(ticks_file)
        run_group([cmd], env, RUN_TIMEOUT_S)
        summary = json.loads((out / "summary.json").read_text())
        if summary["exit_reason"] != "completed":
            raise RuntimeError(f"graph run did not complete: {summary}")
        if "CLNN_BENCH_PROFILE_DIR" not in env_extra:
            if not ticks_file.exists():
                raise RuntimeError("the latency hook recorded nothing: has the trial manager "
                                   "still a TickJoin and a clock_pub? (SITECUSTOMIZE)")
            record = json.loads(ticks_file.read_text())
            published, completed = record["published"], record["completed"]
            if len(published) != summary["ticks"] or len(completed) != summary["ticks"]:
                raise RuntimeError(f"tick hook: {len(published)} clocks, {len(completed)} "
                                   f"completions for {summary['ticks']} ticks")
            summary["latency_us"] = [(c - p) / 1e3 for p, c in zip(published, completed)]
        return summary

    def ring_rate(self, layout: str, executor: str, msgs: str) -> dict:
        me = [sys.executable, str(Path(__file__).resolve())]
        common = ["--ticks", str(self.sizes["ring_ticks"][layout, executor]), "--msgs", msgs]
        if layout == "composed":
            commands = [me + ["ring-composed", *common]]
        else:  # the trial manager last, as run_all starts it
            commands = [me + ["ring-stage", "--role", role, *common] for role in ROLES]
        return self.run_ring(commands, child_env(CLNN_ROS_EXECUTOR=executor))

    def run_ring(self, commands: list[list[str]], env: dict) -> dict:
        """Run the ring's processes; the trial manager's (the last command's) RING_RESULT. A
        ring process that has not exited TEARDOWN_GRACE_S after the result is in (seen:
        rclpy/Fast DDS teardown hanging once in a while; the teardown is not measured) is
        killed, its own Fast DDS shared-memory files removed, and counted in
        self.forced_ring_exits."""
        from clnn_ros.rosenv import own_fast_dds_files, remove_files_of_dead_process

        base = self.out_dir("ring")
        outs = [base.with_name(f"{base.name}_{i}.out") for i in range(len(commands))]
        errs = [path.with_suffix(".err") for path in outs]
        procs = []

        def kill(p: subprocess.Popen) -> None:
            names = own_fast_dds_files(p.pid)
            kill_group(p)
            p.wait()
            remove_files_of_dead_process(names)

        def tail(i: int) -> str:
            return errs[i].read_text(errors="replace")[-2000:]

        try:
            for c, out, err in zip(commands, outs, errs):
                with open(out, "w") as o, open(err, "w") as e:
                    procs.append(subprocess.Popen(c, cwd=REPO, env=env, stdin=subprocess.DEVNULL,
                                                  stdout=o, stderr=e, start_new_session=True))
            deadline = time.monotonic() + RUN_TIMEOUT_S
            result = result_at = None
            while any(p.poll() is None for p in procs):
                now = time.monotonic()
                if result is None:
                    line = next((l for l in outs[-1].read_text().splitlines()
                                 if l.startswith("RING_RESULT ")), None)
                    if line is not None:
                        result, result_at = json.loads(line.split(" ", 1)[1]), now
                if result is not None and now - result_at > TEARDOWN_GRACE_S:
                    hung = [p for p in procs if p.poll() is None]
                    for p in hung:
                        kill(p)
                    self.forced_ring_exits += len(hung)
                    print(f"  (ring: {len(hung)} process(es) hung at teardown after the "
                          f"result; killed)", file=sys.stderr, flush=True)
                    return result
                if now > deadline:
                    raise RuntimeError(f"ring timed out ({' '.join(commands[-1][-8:])}):\n"
                                       + "\n".join(tail(i) for i in range(len(procs))))
                time.sleep(0.05)
        except BaseException:
            for p in procs:
                if p.poll() is None:
                    kill(p)
            raise
        failed = [f"{' '.join(c[-8:])}: exit {p.returncode}\n{tail(i)}"
                  for i, (p, c) in enumerate(zip(procs, commands)) if p.returncode != 0]
        if failed or result is None:
            line = next((l for l in outs[-1].read_text().splitlines()
                         if l.startswith("RING_RESULT ")), None)
            if failed or line is None:
                raise RuntimeError("ring failed:\n" + ("\n".join(failed) or tail(-1)))
            result = json.loads(line.split(" ", 1)[1])
        return result

    def paced_run(self, hogs: int) -> dict:
        """The 50 Hz run with `hogs` busy processes beside it (started before run_all, killed
        after it in any case)."""
        out = self.out_dir(f"paced_{hogs}")
        record = out.with_name(out.name + "_paced.json")
        env_node = (f"python {shlex.quote(str(Path(__file__).resolve()))} paced-env "
                    f"--period-ms {PERIOD_MS:g} --out {shlex.quote(str(record))}")
        cmd = [sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--trials",
               str(self.sizes["paced_trials"]), "--seed", str(SEED), "--out", str(out),
               "--env-node", env_node]
        procs = []
        try:
            for _ in range(hogs):
                procs.append(subprocess.Popen([sys.executable, "-c", HOG,
                                               str(PACED_TIMEOUT_S + 30)],
                                              stdin=subprocess.DEVNULL))
            if hogs:
                time.sleep(1.0)  # the hogs are busy before the graph starts
            began, sampler = time.monotonic(), CpuSampler()
            try:
                run_group([cmd], child_env(CLNN_ROS_EXECUTOR="events"), PACED_TIMEOUT_S)
            finally:
                sampler.stop()
            wall = time.monotonic() - began
        finally:
            for p in procs:
                p.kill()
            for p in procs:
                p.wait()
        summary = json.loads((out / "summary.json").read_text())
        if summary["exit_reason"] != "completed":
            raise RuntimeError(f"paced run did not complete: {summary}")
        data = json.loads(record.read_text())
        period = data["period_ns"]
        ticks = data["ticks"]
        latencies = [(a - p) / 1e6 for _t, _s, p, a in ticks if a is not None]
        slots = [s for _t, s, _p, _a in ticks]
        busy = sampler.busy_cores(ticks[0][2], ticks[-1][2]) if ticks else float("nan")
        return dict(hogs=hogs, ticks=len(ticks), summary=summary, run_s=wall, busy=busy,
                    answered=len(latencies),
                    within=sum(1 for _t, _s, p, a in ticks
                               if a is not None and a - p <= DEADLINE_MS * 1e6),
                    latency_ms=latencies,
                    late=sum(b - a - 1 for a, b in zip(slots, slots[1:])),
                    span_s=(slots[-1] - slots[0]) * period / 1e9 if slots else 0.0)


# ----------------------------------------------------------------------------- profiles

EXEC = "executor: spin_once (C++ wait, take, C-side deserialization, dispatch)"
TIMESOURCE = "rclpy TimeSource: /clock callbacks of use_sim_time (Python)"
DESER = "deserialization: Python message objects built on receive"
PUBLISH = "publish: Python-to-C conversion, CDR serialization, DDS write"
CONSTRUCT = "message construction and field setting in the nodes"
NODE = "node callbacks: Python (clnn_ros/nodes)"
NODE_NUMPY = "numpy called by the nodes"
CORE = "core model (clnn_ros/core, with its numpy)"
OTHER = "other"
CATEGORIES = (EXEC, TIMESOURCE, DESER, PUBLISH, CONSTRUCT, NODE, NODE_NUMPY, CORE, OTHER)
SUMMARY_GROUPS = (("executor", (EXEC,)), ("TimeSource", (TIMESOURCE,)),
                  ("serialization (publish + received message objects)", (PUBLISH, DESER)),
                  ("Python callback work (construction, callbacks, numpy)",
                   (CONSTRUCT, NODE, NODE_NUMPY)), ("core model", (CORE,)))
MSG, INHERIT = "msg", "inherit"


def own_category(func) -> str:
    """A function's own category, or MSG (a generated message class) / INHERIT (numpy,
    stdlib, builtins, rclpy's clock and time): those take the category of their callers."""
    filename, _line, name = func
    f = filename.replace("\\", "/")
    if filename == "~":  # a builtin
        if "spin_once" in name or "WaitSet" in name or "wait_set" in name:
            return EXEC
        if "publish" in name:
            return PUBLISH
        return INHERIT
    if "/msg/_" in f:
        return MSG
    if "/rclpy/publisher.py" in f:
        return PUBLISH
    if "/rclpy/time_source.py" in f:
        return TIMESOURCE
    if any(part in f for part in ("/rclpy/executors.py", "/rclpy/experimental/",
                                  "/rclpy/task.py", "/rclpy/context.py", "/rclpy/waitable.py",
                                  "/rclpy/subscription.py", "/rclpy/timer.py")):
        return EXEC
    if "/clnn_ros/nodes/" in f:
        return NODE
    if "/clnn_ros/core/" in f:
        return CORE
    if "/clnn_ros/run_all.py" in f:
        return OTHER
    return INHERIT


def is_numpy(func) -> bool:
    filename, _line, name = func
    return "/numpy/" in filename.replace("\\", "/") or (filename == "~" and "numpy" in name)


def categorize(stats: pstats.Stats) -> dict[str, float]:
    """Exclusive (cProfile tottime) seconds per category. A message-class function counts as
    deserialization when rclpy's executor called it (building a received message) and as
    construction when node code did; numpy and other helpers count for their callers."""
    memo: dict = {}

    def resolve(func, visiting) -> dict[str, float]:
        if func in memo:
            return memo[func]
        own = own_category(func)
        if own not in (MSG, INHERIT):
            return {own: 1.0}
        if func in visiting:
            return {OTHER: 1.0}
        callers = stats.stats[func][4]
        weights = {c: (e[2] or e[1]) for c, e in callers.items() if c in stats.stats}
        total = sum(weights.values())
        shares: dict[str, float] = {}
        if not total:
            shares = {OTHER: 1.0}
        for caller, w in weights.items():
            for cat, frac in resolve(caller, visiting | {func}).items():
                if own == MSG:
                    cat = DESER if cat == EXEC else CONSTRUCT if cat in (NODE, CORE) else cat
                elif cat == NODE and is_numpy(func):
                    cat = NODE_NUMPY
                shares[cat] = shares.get(cat, 0.0) + frac * w / total
        memo[func] = shares
        return shares

    totals = dict.fromkeys(CATEGORIES, 0.0)
    for func, (_cc, _nc, tottime, _ct, _callers) in stats.stats.items():
        for cat, frac in resolve(func, frozenset()).items():
            totals[cat] += tottime * frac
    return totals


def top_functions(stats: pstats.Stats, n: int) -> list[tuple[str, float, int]]:
    rows = []
    for (filename, line, name), (_cc, nc, tottime, _ct, _callers) in stats.stats.items():
        where = name if filename == "~" else \
            f"{Path(filename).parent.name}/{Path(filename).name}:{line}({name})"
        rows.append((where, tottime, nc))
    return sorted(rows, key=lambda r: -r[1])[:n]


def profile_composed(bench: Bench) -> tuple[pstats.Stats, dict]:
    prof, out = bench.work / "composed.prof", bench.out_dir("profile_composed")
    argv = ["--composed", "--quiet", "--no-record", "--trials",
            str(bench.sizes["profile_trials"]), "--seed", str(SEED), "--out", str(out)]
    run_group([[sys.executable, "-c", COMPOSED_PROFILER, str(prof), *argv]],
              child_env(CLNN_ROS_EXECUTOR="events"), RUN_TIMEOUT_S)
    return pstats.Stats(str(prof)), json.loads((out / "summary.json").read_text())


def profile_separate(bench: Bench) -> tuple[dict, dict]:
    profiles = bench.work / "node_profiles"
    profiles.mkdir()
    summary = bench.graph_rate("separate", "events", bench.sizes["profile_trials"],
                               CLNN_BENCH_PROFILE_DIR=profiles)
    found = {p.stem: pstats.Stats(str(p)) for p in sorted(profiles.glob("*.prof"))}
    if not found:
        raise RuntimeError("no node process wrote a profile: has GraphNode still stamp()? "
                           "(SITECUSTOMIZE)")
    return found, summary


# ----------------------------------------------------------------------------- micro-benchmarks

def serialization_cost(repeats: int = 10000) -> dict:
    """Microseconds to serialize one message (the publisher's side) and to deserialize one
    delivery, per topic, for the graph's types ("typed") and for UInt64: {kind: {topic:
    (serialize, deserialize)}}, the best of 3 rounds."""
    from rclpy.serialization import deserialize_message, serialize_message

    result = {}
    for kind in ("uint64", "typed"):
        msgs = ring_messages(kind)
        result[kind] = {}
        for topic, msg in msgs.items():
            data, cls = serialize_message(msg), type(msg)
            best_ser = best_de = float("inf")
            for _ in range(3):
                start = time.perf_counter()
                for _ in range(repeats):
                    serialize_message(msg)
                best_ser = min(best_ser, (time.perf_counter() - start) / repeats)
                start = time.perf_counter()
                for _ in range(repeats):
                    deserialize_message(data, cls)
                best_de = min(best_de, (time.perf_counter() - start) / repeats)
            result[kind][topic] = (1e6 * best_ser, 1e6 * best_de)
    return result


def per_tick_serialization(costs: dict, deliveries: dict) -> tuple[float, float]:
    """(serialize the tick's 5 messages, deserialize its deliveries), microseconds."""
    return (sum(ser for ser, _ in costs.values()),
            sum(de * deliveries[topic] for topic, (_, de) in costs.items()))


# ----------------------------------------------------------------------------- the run

def percentiles(values: list[float]) -> tuple[float, float, float, float]:
    """(p50, p99, max, mean); NaN for none."""
    import numpy as np
    if not values:
        return (float("nan"),) * 4
    a = np.asarray(values, dtype=float)
    return (float(np.percentile(a, 50)), float(np.percentile(a, 99)), float(a.max()),
            float(a.mean()))


def main_benchmark(a) -> int:
    from clnn_ros import rosenv  # noqa: F401  (the project's defaults, for every child too)
    sizes = QUICK if a.quick else FULL
    if not os.environ.get("ROS_DOMAIN_ID"):
        print("benchmark_graph: note: ROS_DOMAIN_ID is not set: ROS domain 0 (give the "
              "benchmark a domain of its own)", file=sys.stderr, flush=True)
    t_start = time.perf_counter()
    load_before = os.getloadavg()
    repeats = sizes["repeats"]
    # (layout, executor, what): the graph, the UInt64 ring, the typed ring (EventsExecutor)
    configs = [(layout, executor, what) for executor in EXECUTORS for layout in LAYOUTS
               for what in ("graph", "uint64", "typed")
               if not (what == "typed" and executor == "single")]
    rates = {c: [] for c in configs}
    ticks, latencies = {}, {}
    spent = dict.fromkeys(EXECUTORS, 0.0)  # seconds of this run per executor's rows
    with tempfile.TemporaryDirectory(prefix="clnn_bench_graph_") as tmp:
        work = Path(tmp)
        os.environ.setdefault("ROS_LOG_DIR", str(work / "ros_log"))
        bench = Bench(sizes, work)
        for rep in range(repeats):  # round robin: a burst of other load hits all alike
            for c in configs:
                layout, executor, what = c
                began = time.monotonic()
                if what == "graph":
                    s = bench.graph_rate(layout, executor, sizes["graph_trials"][executor])
                    ticks[c] = s["ticks"]
                    latencies.setdefault(c, []).extend(s["latency_us"])
                else:
                    s = bench.ring_rate(layout, executor, what)
                rates[c].append(s["ticks_per_s"])
                spent[executor] += time.monotonic() - began
                print(f"  run {rep + 1}/{repeats}: {layout:9s} {executor:7s} {what:7s} "
                      f"{s['ticks_per_s']:7.0f} ticks/s  ({time.monotonic() - began:.0f} s)",
                      flush=True)
        rows = []
        for executor in EXECUTORS:
            for layout in LAYOUTS:
                row = dict(layout=layout, executor=executor,
                           ticks=ticks[(layout, executor, "graph")],
                           latency=percentiles(latencies[(layout, executor, "graph")]),
                           samples=len(latencies[(layout, executor, "graph")]))
                for what in ("graph", "uint64", "typed"):
                    r = rates.get((layout, executor, what), [])
                    row[what] = (max(r), r) if r else None
                rows.append(row)
        paced = []
        for hogs in (0, HOGS):
            print(f"  {PERIOD_MS:g} ms paced run, {hogs} hogs ...", flush=True)
            p = bench.paced_run(hogs)
            print(f"    {p['within']}/{p['ticks']} answered within {DEADLINE_MS:g} ms, "
                  f"p99 {percentiles(p['latency_ms'])[1]:.2f} ms", flush=True)
            paced.append(p)
        print("  serialization micro-benchmark, profiles ...", flush=True)
        ser = serialization_cost(2000 if a.quick else 10000)
        composed = profile_composed(bench)
        separate = profile_separate(bench)
        elapsed = time.perf_counter() - t_start
        doc = report(rows, paced, ser, composed, separate, sizes, a.quick, elapsed,
                     (load_before, os.getloadavg()), spent, bench.forced_ring_exits)
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(doc)
    print(doc)
    return 0


# ----------------------------------------------------------------------------- report

def qos_text(description: qos.Qos) -> str:
    """'RELIABLE, KEEP_LAST 2000, VOLATILE': a QoS description as the report states it."""
    return (f"{description.reliability.upper()}, {description.history.upper()} "
            f"{description.depth}, {description.durability.upper()}")


def fmt_rate(best: float, rates: list[float]) -> str:
    if len(rates) > 1:
        return f"{best:.0f} ({min(rates):.0f}-{max(rates):.0f})"
    return f"{best:.0f}"


def per_tick_table(profiles: dict[str, tuple[dict, int]], skip=()) -> list[str]:
    """Microseconds of exclusive time per tick, a column per profile."""
    names = list(profiles)
    lines = ["| category | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]
    for c in CATEGORIES:
        if c in skip:
            continue
        lines.append(f"| {c} | " + " | ".join(
            f"{1e6 * cats[c] / n:.1f}" for cats, n in profiles.values()) + " |")
    lines.append("| **sum** | " + " | ".join(
        f"**{1e6 * sum(v for k, v in cats.items() if k not in skip) / n:.1f}**"
        for cats, n in profiles.values()) + " |")
    return lines


def shown_path(value: str) -> str:
    try:
        return str(Path(value).resolve().relative_to(REPO))
    except ValueError:
        return value


def report(rows, paced, ser, composed, separate, sizes, quick, elapsed, loads, spent,
           forced_ring_exits) -> str:
    repeats = sizes["repeats"]
    events = [r for r in rows if r["executor"] == "events"]
    by_layout = {r["layout"]: r for r in events}
    ring = sizes["ring_ticks"]
    lines = [
        "# Benchmark: the ROS 2 graph against a raw DDS lockstep ring",
        "",
        f"Generated by `python scripts/benchmark_graph.py{' --quick' if quick else ''}` in "
        f"{elapsed:.0f} s ({os.cpu_count()} cores, Python {platform.python_version()}, load "
        f"average {loads[0][0]:.1f} before and {loads[1][0]:.1f} after: other work on the "
        "machine slows single runs, hence the best of several). All figures come from this one "
        "run, ratios between runs of this run; do not edit by hand."
        + (" **--quick: one run of each, few ticks: a smoke test, not a measurement.**"
           if quick else ""),
        "",
        "Every process (graph, ring, paced environment) runs under `clnn_ros.rosenv`'s "
        f"defaults: Fast DDS profile `FASTRTPS_DEFAULT_PROFILES_FILE="
        f"{shown_path(os.environ.get('FASTRTPS_DEFAULT_PROFILES_FILE', ''))}` (shared memory with "
        "a 30 s health check + UDPv4), `ROS_AUTOMATIC_DISCOVERY_RANGE="
        f"{os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '')}`, RMW "
        f"`{os.environ.get('RMW_IMPLEMENTATION') or 'rmw_fastrtps_cpp (default)'}`.",
        "",
        "## Throughput: the graph against the raw ring",
        "",
        "* **Graph**: `python -m clnn_ros.run_all --quiet --no-record --seed 1 --trials N` (1 SV), "
        "ticks/s from its summary.json (first tick to last: start-up and discovery "
        "excluded); N = "
        f"{sizes['graph_trials']['events']} ({by_layout['separate']['ticks']} ticks) with the "
        f"EventsExecutor (the default), N = {sizes['graph_trials']['single']} "
        f"({rows[2]['ticks']} ticks) with rclpy's SingleThreadedExecutor "
        "(`CLNN_ROS_EXECUTOR=single`, read by `clnn_ros/nodes/common.py:make_executor`). The "
        "runs carry the latency hook (below): two clock readings and two list appends per tick "
        "in the trial manager, under 1 us of a tick.",
        "* **Raw ring**: 5 nodes (in 5 processes, or composed in 1 on one executor) that "
        "exchange exactly the lockstep messages of a tick and do nothing else: clock to the "
        "environment, state to encoder + reward + trial manager, spikes and reward to agent + "
        "trial manager, action to environment + trial manager: 5 publications and 10 "
        "deliveries per tick, 4 hops on the critical path; each node publishes once it holds "
        "its inputs of the tick, as in the graph. The graph's QoS object "
        f"(`LOCKSTEP_QOS`: {qos_text(qos.LOCKSTEP)}) and executor factory "
        "(`make_executor`). *UInt64*: std_msgs/UInt64 messages (the transport alone); "
        "*typed*: the graph's own message types with fixed content (transport + "
        "serialization of the real messages; no model, no message construction). Ticks: "
        f"{ring['separate', 'events']} (5 processes) and {ring['composed', 'events']} "
        f"(composed) with the EventsExecutor, {ring['separate', 'single']} with the "
        "SingleThreadedExecutor.",
        "* What the graph does beyond the ring, and pays for in these ratios: each clock also "
        "goes to rclpy's TimeSource in the 4 nodes with use_sim_time (4 more deliveries per "
        "tick, each a Python callback), every input passes its content rule and its tick "
        "check, the nodes fill their messages from the model, and trial events, weights and "
        "checkpoints come at each trial's end.",
        f"* Each figure is the best of {repeats} run{'s' if repeats > 1 else ''}, run round robin"
        + (" (range in parentheses)." if repeats > 1 else ".")
        + f" The EventsExecutor rows took {spent['events']:.0f} s of this run, the "
        f"SingleThreadedExecutor rows (fewer ticks) {spent['single']:.0f} s."
        + (f" {forced_ring_exits} ring process(es) hung in their teardown after the result "
           "(not measured) and were killed." if forced_ring_exits else ""),
        "",
        "| layout | executor | graph ticks/s | raw ring ticks/s (UInt64) | graph / raw ring | "
        "typed ring ticks/s | graph / typed ring |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        g, u, t = r["graph"], r["uint64"], r["typed"]
        lines.append(
            f"| {LAYOUT_NAMES[r['layout']]} | {EXECUTOR_NAMES[r['executor']]} | {fmt_rate(*g)} | "
            f"{fmt_rate(*u)} | **{100 * g[0] / u[0]:.0f}%** | {fmt_rate(*t) if t else '-'} | "
            f"{f'{100 * g[0] / t[0]:.0f}%' if t else '-'} |")
    lines += ["", "Targets (EventsExecutor, graph / raw UInt64 ring): at least "
              f"{100 * TARGETS['separate']:.0f}% in 5 processes and "
              f"{100 * TARGETS['composed']:.0f}% composed, aiming at {100 * AIM:.0f}%:", ""]
    for layout in LAYOUTS:
        r = by_layout[layout]
        ratio = r["graph"][0] / r["uint64"][0]
        verdict = "**met**" if ratio >= TARGETS[layout] else "**missed**"
        aim = "the aim reached too" if ratio >= AIM else \
            f"{100 * (AIM - ratio):.0f} points short of the aim"
        lines.append(f"* {LAYOUT_NAMES[layout]}: {100 * ratio:.0f}% against "
                     f"{100 * TARGETS[layout]:.0f}%: {verdict} ({aim}).")
    lines.append("")

    lines += [
        "## Per-tick latency of the graph",
        "",
        "Measured in the throughput runs above (all of their ticks, every repeat): in the "
        "trial manager, the wall time from publishing clock(t) to holding state(t) and "
        "action(t), i.e. one tick's whole round trip trial manager -> environment -> encoder "
        "and reward -> agent -> trial manager (the state reaches the trial manager on the "
        "way). A hook that the benchmark puts into run_all's processes through a temporary "
        "`sitecustomize.py` (run_all and the nodes run unchanged) wraps the trial manager's "
        "clock publisher (the reading just before `publish`) and its `TickJoin` completion "
        "(the reading when the tick's last input is in, before `on_tick`). What the trial "
        "manager does between two ticks (trial events, trials.csv at a trial's end) falls "
        "outside the latency and inside the tick period.",
        "",
        "| layout | executor | ticks | p50 us | p99 us | max us | mean us | mean tick period us |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        p50, p99, mx, mean = r["latency"]
        period = sum(1e6 / x for x in r["graph"][1]) / len(r["graph"][1])
        lines.append(f"| {LAYOUT_NAMES[r['layout']]} | {EXECUTOR_NAMES[r['executor']]} | "
                     f"{r['samples']} | {p50:.0f} | {p99:.0f} | {mx:.0f} | {mean:.0f} | "
                     f"{period:.0f} |")
    lines.append("")

    lines += [
        f"## {1000 / PERIOD_MS:g} Hz, paced by the environment",
        "",
        "As a robot runs it: `python -m clnn_ros.run_all --quiet --seed 1 --trials "
        f"{sizes['paced_trials']} --env-node \"python scripts/benchmark_graph.py paced-env "
        f"--period-ms {PERIOD_MS:g} --out FILE\"` (5 processes, EventsExecutor, the recorder on "
        "as by default). The environment node of the script (`paced-env`: the project's "
        "`EnvironmentNode` with its state publication paced) publishes state(t) at the first "
        f"slot of a {PERIOD_MS:g} ms wall-clock grid (anchored at state 0) once its inputs "
        "clock(t) and action(t-1) are in, waiting for the slot inside its callback; a tick "
        "whose inputs come after its slot goes out at the next free slot (a *late slot*). For "
        "each tick it notes the time just before publishing state(t) and the time the agent's "
        "action(t) reaches its callback (time.monotonic_ns): the latency state -> action "
        "(environment -> encoder and reward -> agent -> environment: 3 hops). "
        f"*Within {DEADLINE_MS:g} ms*: the share of all ticks whose action came back within "
        f"{DEADLINE_MS:g} ms of its state (a tick whose action never came counts as missed). "
        f"*Hogs*: {HOGS} processes `python -c 'while ...: pass'` (2 x cores, at least 4; each "
        "ends by itself after a time limit in any case) started 1 s before run_all and killed "
        "after it, at the graph's priority.",
        "",
        f"| condition | ticks | within {DEADLINE_MS:g} ms | p50 ms | p99 ms | max ms | "
        "late slots | run_all wall s | busy cores |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for p in paced:
        p50, p99, mx, _mean = percentiles(p["latency_ms"])
        name = "idle" if not p["hogs"] else f"{p['hogs']} CPU hogs on {os.cpu_count()} cores"
        lines.append(f"| {name} | {p['ticks']} | **{100 * p['within'] / max(p['ticks'], 1):.1f}%** "
                     f"({p['within']}) | {p50:.2f} | {p99:.2f} | {mx:.2f} | {p['late']} | "
                     f"{p['run_s']:.0f} | {p['busy']:.2f} |")
    lines += ["", f"*Busy cores*: the machine's average busy cores (of {os.cpu_count()}) from "
              "the first state to the last, every process counted (/proc/stat, sampled every "
              "0.25 s): the graph and its recorder at 50 Hz, the hogs, and whatever else ran on "
              "the machine then (an \"idle\" figure well above the graph's own share means "
              "other work ran beside it).", ""]

    ring_deliveries = {topic: len(subscribers) for topic, (_, subscribers) in EDGES.items()}
    graph_deliveries = {**ring_deliveries, "clock": ring_deliveries["clock"] + TIME_SOURCES}
    u_ser, u_de = per_tick_serialization(ser["uint64"], ring_deliveries)
    t_ser, t_de = per_tick_serialization(ser["typed"], ring_deliveries)
    g_de = per_tick_serialization(ser["typed"], graph_deliveries)[1]
    (c_stats, c_summary), (n_stats, n_summary) = composed, separate
    c_ticks, n_ticks = c_summary["ticks"], n_summary["ticks"]
    c_cats = categorize(c_stats)
    n_cats = {name: categorize(st) for name, st in n_stats.items()}
    n_total = {c: sum(cats[c] for cats in n_cats.values()) for c in CATEGORIES}

    def shares(cats: dict) -> str:
        total = sum(v for k, v in cats.items() if k != OTHER) or 1.0
        return ", ".join(f"{label} {100 * sum(cats[c] for c in group) / total:.0f}%"
                         for label, group in SUMMARY_GROUPS)

    lines += ["## Summary", ""]
    for r in events:
        g, u, t = r["graph"][0], r["uint64"][0], r["typed"][0]
        lines.append(
            f"* {LAYOUT_NAMES[r['layout']]}, EventsExecutor: {1e6 / g:.0f} us per tick in the "
            f"graph, {1e6 / u:.0f} us in the UInt64 ring, {1e6 / t:.0f} us in the typed ring: "
            f"the graph's message types cost {1e6 / t - 1e6 / u:.0f} us per tick, the rest of "
            f"the graph (TimeSource, content rules, message construction, callbacks, model) "
            f"{1e6 / g - 1e6 / t:.0f} us.")
    lines += [
        f"* Profile shares (EventsExecutor, \"other\" left out): composed: {shares(c_cats)}; "
        f"5 node processes together (CPU time): {shares(n_total)}.",
        "",
        "## Where the time goes",
        "",
        "Serialization alone (rclpy.serialization in one process, no DDS; Python message "
        "object <-> C conversion + CDR), microseconds: one message of each topic of a tick "
        "(with the content of a typical tick) serialized once, one delivery deserialized; "
        "deliveries per tick in the ring and in the graph (where each clock also goes to the "
        f"{TIME_SOURCES} TimeSources):",
        "",
        "| topic | type | serialize | deserialize | ring deliveries | graph deliveries |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for topic, (t_s, t_d) in ser["typed"].items():
        lines.append(f"| {topic} | {type_name(topic)} | {t_s:.2f} | {t_d:.2f} | "
                     f"{ring_deliveries[topic]} | {graph_deliveries[topic]} |")
    lines += [
        "",
        "Per tick (5 messages serialized, every delivery deserialized):",
        "",
        "| messages | serialize 5 | deserialize the ring's 10 | total |",
        "|---|---:|---:|---:|",
        f"| std_msgs/UInt64 | {u_ser:.1f} | {u_de:.1f} | {u_ser + u_de:.1f} |",
        f"| the graph's types | {t_ser:.1f} | {t_de:.1f} | {t_ser + t_de:.1f} |",
        f"| the graph's types, the graph's {sum(graph_deliveries.values())} deliveries | "
        f"{t_ser:.1f} | {g_de:.1f} | {t_ser + g_de:.1f} |",
        "",
        f"cProfile, EventsExecutor, {sizes['profile_trials']} trials, no recorder. Exclusive "
        "time in microseconds per tick; message-class code counts as deserialization when the "
        "executor called it and as construction when a node did; numpy and other helpers count "
        "for their callers; rclpy's time_source.py (the TimeSource's /clock callback) is its "
        "own category. cProfile inflates Python-level work (many small calls) more than C++ "
        "(executor, publish): read the shares, not the absolute figures.",
        "",
        f"The composed graph ({c_ticks} ticks, {c_summary['ticks_per_s']:.0f} ticks/s with the "
        "profiler on; profiled from the trial manager's `publish_clock(0)` to its `stop()`, "
        "wall-clock timer: its one thread is busy nearly all the time, the sum is close to "
        "1e6 / ticks/s):",
        "",
    ]
    lines += per_tick_table({"composed": (c_cats, c_ticks)})
    lines += ["", f"The 5-process graph with each node process profiled ({n_ticks} ticks, "
                  f"{n_summary['ticks_per_s']:.0f} ticks/s with the profilers on), each from its "
                  "first publication (`GraphNode.stamp`) to its exit, with a CPU-time timer "
                  "(`time.thread_time`: the CPU of the thread that runs the executor and the "
                  "callbacks, so waiting for the other processes does not count; it costs a "
                  "system call per event and inflates Python work more than the wall clock does; "
                  "the DDS library's own threads are not seen). \"other\" (the shutdown) is "
                  "left out:", ""]
    lines += per_tick_table({name: (cats, n_ticks) for name, cats in n_cats.items()},
                            skip=(OTHER,))
    missing = [n for n in ROLES if n not in n_cats]
    if missing:
        lines += ["", f"(No profile from {', '.join(missing)}: the process did not exit by "
                      "itself; run_all terminated it after its grace period.)"]
    lines += ["", "Top functions of the composed run (exclusive time):", "",
              "| function | s | calls |", "|---|---:|---:|"]
    lines += [f"| `{w}` | {t:.3f} | {n} |" for w, t, n in top_functions(c_stats, 15)]
    if n_stats:
        merged = pstats.Stats()
        merged.add(*n_stats.values())
        lines += ["", "Top functions of the 5 node processes together (CPU time):", "",
                  "| function | s | calls |", "|---|---:|---:|"]
        lines += [f"| `{w}` | {t:.3f} | {n} |" for w, t, n in top_functions(merged, 15)]
    lines.append("")
    return "\n".join(lines)


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "paced-env":  # run_all --env-node (ROS arguments)
        return paced_env(sys.argv[2:])
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="mode")
    for mode in ("ring-stage", "ring-composed"):
        p = sub.add_parser(mode, help="internal: one raw-ring run")
        p.add_argument("--executor", choices=EXECUTORS,
                       help="default: CLNN_ROS_EXECUTOR, as the graph's nodes")
        p.add_argument("--ticks", type=int, default=FULL["ring_ticks"]["separate", "events"])
        p.add_argument("--msgs", choices=("uint64", "typed"), default="uint64")
        if mode == "ring-stage":
            p.add_argument("--role", choices=ROLES, required=True)
    sub.add_parser("paced-env", help="internal: the environment node of the paced run "
                                     "(run_all --env-node)")
    parser.add_argument("--out", type=Path, help="the report (default docs/benchmark_graph.md; "
                        "none with --quick)")
    parser.add_argument("--quick", action="store_true",
                        help="one run of each with few ticks (a smoke test, about 1.5 min)")
    a = parser.parse_args()
    if a.mode is None:
        if a.out is None and not a.quick:
            a.out = REPO / "docs" / "benchmark_graph.md"
        return main_benchmark(a)
    from clnn_ros import rosenv  # noqa: F401  (the graph's DDS defaults, before rclpy loads)
    if a.executor:
        os.environ["CLNN_ROS_EXECUTOR"] = a.executor
    return ring_stage(a) if a.mode == "ring-stage" else ring_composed(a)


if __name__ == "__main__":
    sys.exit(main())
