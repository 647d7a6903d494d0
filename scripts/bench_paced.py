"""The benchmark's 50 Hz run (scripts/benchmark_graph.py), paced as a user paces a run at robot
speed: `run_all --rate 50` (the trial manager releases at most one tick per 20 ms period of a
steady timer), with the environment node of this script timing each tick (`run_all --env-node
"python scripts/benchmark_graph.py timed-env ..."`); idle and beside CPU hogs, with how busy the
machine was meanwhile."""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

from bench_node import Publishing
from bench_processes import child_env, run_group
from bench_settings import DEADLINE_MS, PACED_TIMEOUT_S, PERIOD_MS, REPO, SEED

HOGS = max(4, 2 * (os.cpu_count() or 1))
# A busy process that ends by itself after argv[1] seconds, should the benchmark be killed.
HOG = ("import sys, time\nend = time.monotonic() + float(sys.argv[1])\n"
       "while time.monotonic() < end:\n    for _ in range(100000):\n        pass\n")
BENCHMARK = REPO / "scripts" / "benchmark_graph.py"


def timed_env(argv: list[str]) -> int:
    """The environment node of the 50 Hz run, as run_all --env-node starts it:
    `timed-env --out FILE --ros-args ...`. The paper's cart-pole (EnvironmentNode), noting when
    each state went out and when the agent's action of that tick came in; it writes them to FILE
    at the end: {"ticks": [[tick, published_ns, answered_ns or null], ...]} (time.monotonic_ns,
    the same clock in every process)."""
    split = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    parser = argparse.ArgumentParser(prog="benchmark_graph.py timed-env")
    parser.add_argument("--out", type=Path, required=True)
    own = parser.parse_args(argv[:split])

    from clnn_ros.nodes.environment import EnvironmentNode
    from clnn_ros.nodes.glue import run_node

    class TimedEnvironmentNode(EnvironmentNode):
        def __init__(self, run: dict):
            super().__init__(run)
            self.state_pub = Publishing(self.state_pub, self.note_publication)
            self.published = {}  # tick: ns
            self.answered = {}   # tick: ns, when the action of the tick came in

        def note_publication(self, state) -> None:
            self.published[state.tick] = time.monotonic_ns()

        def on_action(self, action) -> None:
            self.answered.setdefault(action.tick, time.monotonic_ns())
            super().on_action(action)

    made = []
    status = run_node(lambda run: made.append(TimedEnvironmentNode(run)) or made[-1],
                      [sys.argv[0], *argv[split:]])
    if made:
        node = made[0]
        own.out.parent.mkdir(parents=True, exist_ok=True)
        own.out.write_text(json.dumps({"ticks": [
            [tick, ns, node.answered.get(tick)] for tick, ns in sorted(node.published.items())]}))
    return status



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


def paced_run(bench, hogs: int) -> dict:
    """The 50 Hz run with `hogs` busy processes beside it (started before run_all, killed
    after it in any case)."""
    out = bench.out_dir(f"paced_{hogs}")
    record = out.with_name(out.name + "_paced.json")
    env_node = f"python {shlex.quote(str(BENCHMARK))} timed-env --out {shlex.quote(str(record))}"
    cmd = [sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--trials",
           str(bench.sizes["paced_trials"]), "--seed", str(SEED), "--out", str(out),
           "--rate", f"{1000 / PERIOD_MS:g}", "--env-node", env_node]
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
    ticks = json.loads(record.read_text())["ticks"]
    latencies = [(a - p) / 1e6 for _t, p, a in ticks if a is not None]
    period_ns = PERIOD_MS * 1e6
    # The pace's periods that passed without a tick: a tick whose round trip overran its period
    # is released at the next one. From the span (each state goes out within its period).
    span = ticks[-1][1] - ticks[0][1] if ticks else 0
    late = max(0, round(span / period_ns) - (len(ticks) - 1))
    busy = sampler.busy_cores(ticks[0][1], ticks[-1][1]) if ticks else float("nan")
    return dict(hogs=hogs, ticks=len(ticks), summary=summary, run_s=wall, busy=busy,
                answered=len(latencies),
                within=sum(1 for _t, p, a in ticks
                           if a is not None and a - p <= DEADLINE_MS * 1e6),
                latency_ms=latencies, late=late, span_s=span / 1e9)
