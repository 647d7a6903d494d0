"""Benchmark of the ROS 2 node graph against a raw DDS lockstep ring of the same shape, all
measured in this one run, plus a profile of where the graph's time goes.

    python scripts/benchmark_graph.py [--out docs/benchmark_graph.md] [--quick]

Measured (ticks per second), about 2.5 minutes in all:
  * the graph: `python -m clnn_ros.run_all --quiet --trials N --seed 1 [--no-record]` in 5
    processes and composed in one process, with the EventsExecutor (the default) and with
    rclpy's SingleThreadedExecutor (CLNN_ROS_EXECUTOR=single); ticks_per_s from summary.json;
  * the raw ring: 5 nodes (trial_manager, environment, encoder, reward, agent) that exchange
    exactly the graph's messages of a tick and do nothing else:
        trial_manager --clock--> environment
        environment   --state--> encoder, reward, trial_manager
        encoder       --spikes--> agent, trial_manager
        reward        --reward--> agent, trial_manager
        agent         --action--> environment (for the next tick), trial_manager
    i.e. 5 publications and 10 deliveries per tick, on a critical path of 4 hops
    (clock, state, spikes|reward, action). Each node publishes when it holds the inputs of the
    tick, as the graph's nodes do. Messages are std_msgs/UInt64 (the transport yardstick) and,
    for a second figure, the graph's own message types with fixed content (what serialization
    of the real messages costs, without the model). Same QoS as the graph (RELIABLE,
    KEEP_LAST 64, VOLATILE).
Every configuration runs REPEATS times, round robin; the table gives the best (highest) rate,
the least disturbed by other load on this 2-core machine, and the range of all runs.
--quick: one run each (a smoke test).

Profiles (EventsExecutor): the composed graph under cProfile from its first tick to its last,
and one 5-process run with every node process under cProfile with a CPU-time timer (through a
temporary sitecustomize.py, so run_all runs unchanged). Exclusive time is grouped into the
executor, publish (conversion, serialization, DDS write), received message objects
(deserialization), message construction in the nodes, node callbacks, numpy called by the
nodes, the core model and other; plus a micro-benchmark of serialization alone.

DDS stays on loopback (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST unless set); run it alone on
the machine, or give it its own ROS_DOMAIN_ID.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import pstats
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SEED = 1
# seed 1, 1 SV: 40 trials = 11150 ticks (the ticks per trial grow little while it learns)
GRAPH_TRIALS = {"events": 40, "single": 8}  # SingleThreadedExecutor: ~600 ticks/s, fewer ticks
RING_TICKS = {"events": 5000, "single": 2000}
PROFILE_TRIALS = 8  # 1912 ticks: the profilers slow the graph 2-4x
REPEATS = 3
RUN_TIMEOUT_S = 120
LAYOUTS = ("separate", "composed")
EXECUTORS = ("events", "single")

ROLES = ("environment", "encoder", "reward", "agent", "trial_manager")
# topic: (publishing role, subscribing roles); the graph's /clock, /cartpole/state,
# /rln/spikes, /rln/reward and /rln/action
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
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.task import Future

    qos = QoSProfile(depth=64, reliability=ReliabilityPolicy.RELIABLE,
                     history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
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


def make_executor(name: str, context=None):
    if name == "single":
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor(context=context)
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)


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
    rclpy.init()
    nodes = {role: ring_node(role, a.msgs, a.ticks) for role in ROLES}
    executor = make_executor(a.executor)
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
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    latched = QoSProfile(depth=16, reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    rclpy.init()
    node = ring_node(a.role, a.msgs, a.ticks)
    executor = make_executor(a.executor)
    executor.add_node(node)
    status = 0
    if a.role == "trial_manager":
        ready = set()
        node.create_subscription(String, f"{RING_NS}/ready", lambda m: ready.add(m.data), latched)
        stop = node.create_publisher(String, f"{RING_NS}/stop", latched)
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
        node.create_subscription(String, f"{RING_NS}/stop", stopped.append, latched)
        ready = node.create_publisher(String, f"{RING_NS}/ready", latched)
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


# ----------------------------------------------------------------------------- orchestration

def child_env(**extra) -> dict:
    env = dict(os.environ)
    env.update({k: str(v) for k, v in extra.items()})
    return env


def run_group(commands: list[list[str]], env: dict, timeout: float) -> list[str]:
    """Start the commands (each in its own process group), wait for all; on timeout kill
    them all. Returns each one's stdout; raises on a failure."""
    procs = [subprocess.Popen(c, cwd=REPO, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, start_new_session=True)
             for c in commands]
    deadline = time.monotonic() + timeout
    outputs, failed = [], []
    for p, c in zip(procs, commands):
        try:
            out, err = p.communicate(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            for q in procs:
                if q.poll() is None:
                    os.killpg(q.pid, signal.SIGKILL)
            out, err = p.communicate()
            failed.append(f"{' '.join(c[-6:])}: timed out\n{err[-2000:]}")
            continue
        outputs.append(out)
        if p.returncode != 0:
            failed.append(f"{' '.join(c[-6:])}: exit {p.returncode}\n{err[-2000:]}")
    if failed:
        raise RuntimeError("\n".join(failed))
    return outputs


def graph_rate(layout: str, executor: str, trials: int, work: Path, env_extra=None) -> dict:
    out = work / f"graph_{layout}_{executor}_{time.monotonic_ns()}"
    cmd = [sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--trials", str(trials),
           "--seed", str(SEED), "--out", str(out), *RUN_ALL_EXTRA]
    if layout == "composed":
        cmd.append("--composed")
    run_group([cmd], child_env(CLNN_ROS_EXECUTOR=executor, **(env_extra or {})), RUN_TIMEOUT_S)
    summary = json.loads((out / "summary.json").read_text())
    if summary["exit_reason"] != "completed":
        raise RuntimeError(f"graph run did not complete: {summary}")
    return summary


def run_all_extra() -> list[str]:
    """--no-record where run_all has it: the graph alone, without the MCAP recorder (its own
    process, subscribed to every topic), as the ring has no recorder either."""
    import importlib.util
    source = Path(importlib.util.find_spec("clnn_ros.run_all").origin).read_text()
    return ["--no-record"] if '"--no-record"' in source else []


RUN_ALL_EXTRA: list[str] = []


def ring_rate(layout: str, executor: str, msgs: str, ticks: int) -> dict:
    me = [sys.executable, str(Path(__file__).resolve())]
    common = ["--executor", executor, "--ticks", str(ticks), "--msgs", msgs]
    if layout == "composed":
        commands = [me + ["ring-composed", *common]]
    else:  # the trial manager last, as run_all starts it
        commands = [me + ["ring-stage", "--role", role, *common] for role in ROLES]
    outputs = run_group(commands, child_env(), RUN_TIMEOUT_S)
    line = next(l for o in outputs for l in o.splitlines() if l.startswith("RING_RESULT "))
    return json.loads(line.split(" ", 1)[1])


# ----------------------------------------------------------------------------- profiles

# Every node process of a run_all run profiles itself when CLNN_BENCH_PROFILE_DIR is set
# (this file goes on its PYTHONPATH); run_all itself is run unchanged.
SITECUSTOMIZE = '''
import os
_dir = os.environ.get("CLNN_BENCH_PROFILE_DIR")
if _dir:
    try:
        _cmd = open("/proc/self/cmdline", "rb").read().split(b"\\0")
    except OSError:
        _cmd = []
    _name = next((c.decode().rsplit(".", 1)[1] for c in _cmd
                  if c.startswith(b"clnn_ros.nodes.")), None)
    if _name:
        import atexit, cProfile, time
        _profile = cProfile.Profile(time.thread_time)
        atexit.register(lambda: (_profile.disable(),
                                 _profile.dump_stats(os.path.join(_dir, _name + ".prof"))))
        _profile.enable()
'''

# The composed run profiles from the first tick to the end of the episode when the trial
# manager has the hooks (start_trial(tick), stop(...)); otherwise the whole of main().
COMPOSED_PROFILER = '''
import cProfile, sys
from clnn_ros import run_all
from clnn_ros.nodes import trial_manager
profile = cProfile.Profile()
TM = trial_manager.TrialManagerNode
if hasattr(TM, "start_trial") and hasattr(TM, "stop"):
    start_trial, stop = TM.start_trial, TM.stop
    def profiled_start(self, tick, *rest, **kw):
        if tick == 0:
            profile.enable()
        return start_trial(self, tick, *rest, **kw)
    def profiled_stop(self, *rest, **kw):
        profile.disable()
        return stop(self, *rest, **kw)
    TM.start_trial, TM.stop = profiled_start, profiled_stop
    status = run_all.main(sys.argv[2:])
else:
    status = profile.runcall(run_all.main, sys.argv[2:])
profile.dump_stats(sys.argv[1])
raise SystemExit(status)
'''

EXEC = "executor: spin_once (C++ wait, take, C-side deserialization, dispatch)"
DESER = "deserialization: Python message objects built on receive"
PUBLISH = "publish: Python-to-C conversion, CDR serialization, DDS write"
CONSTRUCT = "message construction and field setting in the nodes"
NODE = "node callbacks: Python (clnn_ros/nodes)"
NODE_NUMPY = "numpy called by the nodes"
CORE = "core model (clnn_ros/core, with its numpy)"
OTHER = "other"
CATEGORIES = (EXEC, DESER, PUBLISH, CONSTRUCT, NODE, NODE_NUMPY, CORE, OTHER)
SUMMARY_GROUPS = (("executor", (EXEC,)), ("serialization (publish + received message objects)",
                                          (PUBLISH, DESER)),
                  ("Python callback work (construction, callbacks, numpy)",
                   (CONSTRUCT, NODE, NODE_NUMPY)), ("core model", (CORE,)))
MSG, INHERIT = "msg", "inherit"


def own_category(func) -> str:
    """A function's own category, or MSG (a generated message class) / INHERIT (numpy,
    stdlib, builtins): those take the category of their callers."""
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


def profile_composed(trials: int, work: Path) -> tuple[pstats.Stats, dict]:
    prof, out = work / "composed.prof", work / "profile_composed"
    argv = ["--composed", "--quiet", "--trials", str(trials), "--seed", str(SEED), "--out",
            str(out), *RUN_ALL_EXTRA]
    run_group([[sys.executable, "-c", COMPOSED_PROFILER, str(prof), *argv]],
              child_env(CLNN_ROS_EXECUTOR="events"), RUN_TIMEOUT_S)
    return pstats.Stats(str(prof)), json.loads((out / "summary.json").read_text())


def profile_separate(trials: int, work: Path) -> tuple[dict, dict]:
    site, profiles = work / "site", work / "node_profiles"
    site.mkdir()
    profiles.mkdir()
    (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
    pythonpath = os.pathsep.join(filter(None, [str(site), os.environ.get("PYTHONPATH")]))
    summary = graph_rate("separate", "events", trials, work,
                         env_extra={"CLNN_BENCH_PROFILE_DIR": profiles, "PYTHONPATH": pythonpath})
    return {p.stem: pstats.Stats(str(p)) for p in sorted(profiles.glob("*.prof"))}, summary


# ----------------------------------------------------------------------------- micro-benchmarks

def serialization_cost(repeats: int = 10000) -> dict:
    """Microseconds per tick to serialize the tick's 5 messages (the publishers' side) and
    deserialize its 10 deliveries, for the graph's types and for UInt64."""
    from rclpy.serialization import deserialize_message, serialize_message

    result = {}
    for kind in ("uint64", "typed"):
        msgs = ring_messages(kind)
        data = {t: serialize_message(m) for t, m in msgs.items()}
        deliveries = [(data[t], type(msgs[t])) for t, (_, subs) in EDGES.items() for _ in subs]
        best_ser = best_de = float("inf")
        for _ in range(3):
            start = time.perf_counter()
            for _ in range(repeats):
                for m in msgs.values():
                    serialize_message(m)
            best_ser = min(best_ser, (time.perf_counter() - start) / repeats)
            start = time.perf_counter()
            for _ in range(repeats):
                for d, t in deliveries:
                    deserialize_message(d, t)
            best_de = min(best_de, (time.perf_counter() - start) / repeats)
        result[kind] = (1e6 * best_ser, 1e6 * best_de)
    return result


# ----------------------------------------------------------------------------- the run

def fmt_rate(best: float, rates: list[float]) -> str:
    if len(rates) > 1:
        return f"{best:.0f} ({min(rates):.0f}-{max(rates):.0f})"
    return f"{best:.0f}"


def main_benchmark(a) -> int:
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    t_start = time.perf_counter()
    load_before = os.getloadavg()
    RUN_ALL_EXTRA[:] = run_all_extra()
    repeats = 1 if a.quick else REPEATS
    # (layout, executor, what): the graph, the UInt64 ring, the typed ring (EventsExecutor)
    configs = [(layout, executor, what) for executor in EXECUTORS for layout in LAYOUTS
               for what in ("graph", "uint64", "typed")
               if not (what == "typed" and executor == "single")]
    rates = {c: [] for c in configs}
    ticks = {}
    with tempfile.TemporaryDirectory(prefix="clnn_bench_graph_") as tmp:
        work = Path(tmp)
        os.environ.setdefault("ROS_LOG_DIR", str(work / "ros_log"))
        for rep in range(repeats):  # round robin: a burst of other load hits all alike
            for c in configs:
                layout, executor, what = c
                if what == "graph":
                    s = graph_rate(layout, executor, GRAPH_TRIALS[executor], work)
                    ticks[c] = s["ticks"]
                else:
                    s = ring_rate(layout, executor, what, RING_TICKS[executor])
                rates[c].append(s["ticks_per_s"])
                print(f"  run {rep + 1}/{repeats}: {layout:9s} {executor:7s} {what:7s} "
                      f"{s['ticks_per_s']:7.0f} ticks/s", flush=True)
        rows = []
        for executor in EXECUTORS:
            for layout in LAYOUTS:
                row = dict(layout=layout, executor=executor,
                           ticks=ticks[(layout, executor, "graph")])
                for what in ("graph", "uint64", "typed"):
                    r = rates.get((layout, executor, what), [])
                    row[what] = (max(r), r) if r else None
                rows.append(row)
        print("  serialization micro-benchmark, profiles ...", flush=True)
        ser = serialization_cost()
        composed = profile_composed(PROFILE_TRIALS, work)
        separate = profile_separate(PROFILE_TRIALS, work)
        elapsed = time.perf_counter() - t_start
        doc = report(rows, ser, composed, separate, repeats, elapsed,
                     (load_before, os.getloadavg()))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(doc)
    print(doc)
    return 0


# ----------------------------------------------------------------------------- report

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


def report(rows, ser, composed, separate, repeats, elapsed, loads) -> str:
    names = {"events": "EventsExecutor", "single": "SingleThreadedExecutor"}
    lines = [
        "# Benchmark: the ROS 2 graph against a raw DDS lockstep ring",
        "",
        f"Generated by `python scripts/benchmark_graph.py` in {elapsed:.0f} s "
        f"({os.cpu_count()} cores, Python {platform.python_version()}, load average "
        f"{loads[0][0]:.1f} before and {loads[1][0]:.1f} after: other work on the machine "
        "slows single runs, hence the best of several). All figures come from this one run; "
        "do not edit by hand.",
        "",
        "* **Graph**: `python -m clnn_ros.run_all --quiet --seed 1 --trials N "
        f"{' '.join(RUN_ALL_EXTRA)}` (1 SV), ticks/s from its summary.json (first tick to "
        f"last; start-up and discovery excluded); N = {GRAPH_TRIALS['events']} "
        f"({rows[0]['ticks']} ticks) with the EventsExecutor (the default), "
        f"N = {GRAPH_TRIALS['single']} ({rows[2]['ticks']} ticks) with rclpy's "
        "SingleThreadedExecutor (`CLNN_ROS_EXECUTOR=single`, read by "
        "`clnn_ros/nodes/common.py:make_executor`).",
        "* **Raw ring**: 5 nodes (in 5 processes, or composed in 1) that exchange exactly the "
        "graph's messages of a tick and do nothing else: /clock to the environment, state to "
        "encoder + reward + trial manager, spikes and reward to agent + trial manager, action "
        "to environment + trial manager: 5 publications and 10 deliveries per tick, 4 hops on "
        "the critical path; each node publishes once it holds its inputs of the tick, as in "
        "the graph. Same QoS (RELIABLE, KEEP_LAST 64, VOLATILE). *UInt64*: std_msgs/UInt64 "
        f"messages (the transport alone); *typed*: the graph's own message types with fixed "
        f"content (transport + serialization of the real messages, no model, no message "
        f"construction). {RING_TICKS['events']} ticks with the EventsExecutor, "
        f"{RING_TICKS['single']} with the SingleThreadedExecutor.",
        f"* Each figure is the best of {repeats} runs, run round robin (range in parentheses).",
        "",
        "| layout | executor | graph ticks/s | raw ring ticks/s (UInt64) | graph / raw ring | "
        "typed ring ticks/s | graph / typed ring |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        layout = "5 processes" if r["layout"] == "separate" else "composed (1 process)"
        g, u, t = r["graph"], r["uint64"], r["typed"]
        lines.append(
            f"| {layout} | {names[r['executor']]} | {fmt_rate(*g)} | {fmt_rate(*u)} | "
            f"**{100 * g[0] / u[0]:.0f}%** | {fmt_rate(*t) if t else '-'} | "
            f"{f'{100 * g[0] / t[0]:.0f}%' if t else '-'} |")
    missed = [r for r in rows if r["graph"][0] < 0.7 * r["uint64"][0]]
    lines += ["", "Target, graph >= 70% of the raw ring: " + (
        "met in every layout." if not missed else "met in " + (", ".join(
            f"{r['layout']}/{r['executor']}" for r in rows if r not in missed) or "none") +
        "; missed in " + ", ".join(f"{r['layout']}/{r['executor']}" for r in missed) + "."),
        ""]

    (u_ser, u_de), (t_ser, t_de) = ser["uint64"], ser["typed"]
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
    for r in rows:
        if r["typed"]:
            g, u, t = r["graph"][0], r["uint64"][0], r["typed"][0]
            lines.append(
                f"* {r['layout']}, {names[r['executor']]}: {1e6 / g:.0f} us per tick in the "
                f"graph, {1e6 / u:.0f} us in the UInt64 ring, {1e6 / t:.0f} us in the typed "
                f"ring: the graph's message types cost {1e6 / t - 1e6 / u:.0f} us per tick, "
                f"the nodes' own work (message construction, callbacks, model) "
                f"{1e6 / g - 1e6 / t:.0f} us.")
    lines += [
        f"* Profile shares (EventsExecutor, \"other\" left out): composed: {shares(c_cats)}; "
        f"5 node processes together (CPU time): {shares(n_total)}.",
        "",
    ]
    lines += [
        "## Where the time goes",
        "",
        "Serialization alone (rclpy.serialization in one process, no DDS), microseconds per "
        "tick: the tick's 5 messages serialized once each, its 10 deliveries deserialized "
        "(C conversion + CDR, and on receive the Python message objects):",
        "",
        "| messages | serialize 5 | deserialize 10 | total |",
        "|---|---:|---:|---:|",
        f"| std_msgs/UInt64 | {u_ser:.1f} | {u_de:.1f} | {u_ser + u_de:.1f} |",
        f"| the graph's types | {t_ser:.1f} | {t_de:.1f} | {t_ser + t_de:.1f} |",
        "",
        f"cProfile, EventsExecutor, {PROFILE_TRIALS} trials. Exclusive time in microseconds "
        "per tick; message-class code counts as deserialization when the executor called it "
        "and as construction when a node did; numpy and other helpers count for their "
        "callers. cProfile inflates Python-level work (many small calls) more than C++ "
        "(executor, publish): read the shares, not the absolute figures.",
        "",
        f"The composed graph ({c_ticks} ticks, {c_summary['ticks_per_s']:.0f} ticks/s with the "
        "profiler on, profiled from the first tick to the last, wall-clock timer: its one "
        "thread is busy nearly all the time, the sum is close to 1e6 / ticks/s):",
        "",
    ]
    lines += per_tick_table({"composed": (c_cats, c_ticks)})
    lines += ["", f"The 5-process graph with each node process profiled ({n_ticks} ticks, "
                  f"{n_summary['ticks_per_s']:.0f} ticks/s with the profilers on) with a CPU-time "
                  "timer (`time.thread_time`: the CPU of the thread that runs the executor and "
                  "the callbacks, so waiting for the other processes does not count; it costs "
                  "a system call per event and inflates Python work more than the wall clock "
                  "does; the DDS library's own threads are not seen). \"other\", mostly the "
                  "start-up, is left out:", ""]
    lines += per_tick_table({name: (cats, n_ticks) for name, cats in n_cats.items()},
                            skip=(OTHER,))
    missing = [n for n in ROLES if n not in n_cats]
    if missing:
        lines += ["", f"(No profile from {', '.join(missing)}: the process did not exit by "
                      "itself; run_all terminated it after its grace period.)"]
    lines += ["", "Top functions of the composed run (exclusive time):", "",
              "| function | s | calls |", "|---|---:|---:|"]
    lines += [f"| `{w}` | {t:.3f} | {n} |" for w, t, n in top_functions(c_stats, 15)]
    lines.append("")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="mode")
    for mode in ("ring-stage", "ring-composed"):
        p = sub.add_parser(mode, help="internal: one raw-ring run")
        p.add_argument("--executor", choices=EXECUTORS, default="events")
        p.add_argument("--ticks", type=int, default=RING_TICKS["events"])
        p.add_argument("--msgs", choices=("uint64", "typed"), default="uint64")
        if mode == "ring-stage":
            p.add_argument("--role", choices=ROLES, required=True)
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "benchmark_graph.md")
    parser.add_argument("--quick", action="store_true", help="one run per figure (a smoke test)")
    a = parser.parse_args()
    if a.mode is None:
        return main_benchmark(a)
    from clnn_ros import rosenv  # noqa: F401  (loopback discovery, before rclpy loads)
    return ring_stage(a) if a.mode == "ring-stage" else ring_composed(a)


if __name__ == "__main__":
    sys.exit(main())
