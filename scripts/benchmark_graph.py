"""Benchmark of the ROS 2 node graph against a raw DDS lockstep ring of the same shape, all
measured in this one run: throughput as ratios, per-tick latency, a 50 Hz run (`--rate 50`, as
a robot runs it), idle and under CPU hogs, and a profile of the graph.

    ROS_DOMAIN_ID=N python scripts/benchmark_graph.py [--out docs/benchmark_graph.md] [--quick]

About 6 minutes (--quick: about 2 minutes, one run of each with fewer ticks, a smoke test;
it prints the report and writes it only with --out). The ROS domain is the environment's
ROS_DOMAIN_ID (ROS's default 0 when unset; give the benchmark a domain of its own), DDS discovery
stays on loopback (clnn_ros.session.rosenv's defaults apply to every process started here: the
graph's,
the ring's, the benchmark's own).

1. Throughput (ticks/s): the graph, started as `python -m clnn_ros.run_all --quiet --no-record
   --seed 1 --trials N` starts it (the run's values and node arguments from clnn_ros.graph.run)
   through the benchmark's node entry bench_node.py, in 5 processes and composed in one
   (ticks_per_s from the trial manager's summary.json: first tick to last), against the raw
   ring (bench_ring.py): 5 nodes (trial_manager, environment, encoder, reward, agent)
   that exchange exactly the lockstep messages of a tick and do nothing else:
        trial_manager --clock--> environment
        environment   --state--> encoder, reward, trial_manager   (state: env/observation)
        encoder       --spikes--> agent, trial_manager
        reward        --reward--> agent, trial_manager
        agent         --action--> environment (for the next tick), trial_manager
   i.e. 5 publications and 10 deliveries per tick, 4 hops on the critical path; each node
   publishes once it holds its inputs of the tick, as the graph's nodes do. std_msgs/UInt64
   messages (the transport yardstick) and the graph's own message types with fixed content.
   The ring runs under the same rosenv defaults (its Fast DDS profile file), with the graph's
   QoS object (clnn_ros.nodes.glue.LOCKSTEP_QOS, from clnn_ros.graph.qos.LOCKSTEP; the report
   states its depth) and the graph's executor factory (clnn_ros.session.rclpy_session.make_executor,
   CLNN_ROS_EXECUTOR). EventsExecutor (the
   default) and rclpy's SingleThreadedExecutor (CLNN_ROS_EXECUTOR=single). Every configuration
   runs REPEATS times, round robin; the best (highest) rate counts, the least disturbed by other
   load on the machine, with the range of all runs; a target is met only if the median of the
   rounds' own ratios (graph over ring of the same round) reaches it too. With the
   EventsExecutor also the graph with sim time in every node (bench_settings.OWN_TIME_ROLES
   started with use_sim_time true, as before 2026-12-03): what rclpy's TimeSource and its
   /clock deliveries cost.
2. Per-tick latency of the graph, from the same graph runs: in the trial manager, the wall
   time from publishing clock(t) to holding state(t) and action(t) (one tick's whole round trip
   through the graph), timed by bench_node.py through the trial manager's public attributes:
   its clock publisher (clock_pub) and its TickJoin's completion (join.complete). p50, p99,
   max.
3. 50 Hz, as a user runs the graph at robot speed (bench_paced.py): `run_all --rate 50
   --env-node "python <this script> timed-env ..."` (the recorder on, as run_all runs by
   default): the trial manager releases at most one tick per 20 ms period of a steady timer;
   the environment node (EnvironmentNode, timing its ticks) notes for every tick the time from
   publishing state(t) to receiving the agent's action(t): the share within 20 ms, p50, p99,
   max, and the periods that passed without a tick; idle, and with 2 x cores (at least 4) busy
   `python` processes, killed afterwards (and each ends by itself after a time limit in any
   case).

Profiles (EventsExecutor, bench_profile.py): the composed graph under cProfile from the trial
manager's first clock to its stop (bench_node.py wraps its advance and stop), and one
5-process run with every node process under cProfile with a CPU-time timer from its first
lockstep publication to its exit. An attribute that no longer exists fails the benchmark:
nothing falls back silently to another measurement.
Exclusive time is grouped into the executor, rclpy's TimeSource (/clock for use_sim_time),
publish, received message objects, message construction, node callbacks, numpy, the core model
and other; plus a micro-benchmark of serialization alone. The report: bench_report.py.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from bench_paced import HOGS, paced_run, timed_env
from bench_processes import Bench
from bench_profile import profile_composed, profile_separate, serialization_cost
from bench_report import percentiles, report
from bench_ring import ring_composed, ring_stage
from bench_settings import (DEADLINE_MS, EXECUTORS, FULL, LAYOUTS, PERIOD_MS, QUICK, REPO,
                            ROLES, SHM)


def main_benchmark(a) -> int:
    from clnn_ros.session import rosenv  # noqa: F401  (the project's defaults, for every child too)
    sizes = QUICK if a.quick else FULL
    if not os.environ.get("ROS_DOMAIN_ID"):
        print("benchmark_graph: note: ROS_DOMAIN_ID is not set: ROS domain 0 (give the "
              "benchmark a domain of its own)", file=sys.stderr, flush=True)
    t_start = time.perf_counter()
    load_before = os.getloadavg()
    repeats = sizes["repeats"]
    # (layout, executor, what): the graph, the UInt64 ring, and with the EventsExecutor the typed
    # ring, the graph with sim time in every node ("graph_sim") and the graph and UInt64 ring
    # on shared memory ("*_shm"; the others run on rosenv's default, UDP on loopback)
    configs = [(layout, executor, what) for executor in EXECUTORS for layout in LAYOUTS
               for what in ("graph", "uint64", "typed", "graph_sim", *SHM)
               if not (what in ("typed", "graph_sim", *SHM) and executor == "single")]
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
                transport = "shm" if what in SHM else "udp"
                if what in ("graph", "graph_shm"):
                    s = bench.graph_run(layout, executor, sizes["graph_trials"][executor],
                                        transport=transport)
                    ticks[c] = s["ticks"]
                    latencies.setdefault(c, []).extend(s["latency_us"])
                elif what == "graph_sim":
                    s = bench.graph_run(layout, executor, sizes["graph_trials"][executor],
                                        sim_time_everywhere=True)
                else:
                    s = bench.ring_rate(layout, executor, what.removesuffix("_shm"), transport)
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
                for what in ("graph", "uint64", "typed", "graph_sim", *SHM):
                    r = rates.get((layout, executor, what), [])
                    row[what] = (max(r), r) if r else None
                if (layout, executor, "graph_shm") in latencies:
                    row["latency_shm"] = percentiles(latencies[layout, executor, "graph_shm"])
                rows.append(row)
        paced = []
        for hogs in (0, HOGS):
            print(f"  {PERIOD_MS:g} ms paced run, {hogs} hogs ...", flush=True)
            p = paced_run(bench, hogs)
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


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "timed-env":  # run_all --env-node (ROS arguments)
        return timed_env(sys.argv[2:])
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
    sub.add_parser("timed-env", help="internal: the environment node of the 50 Hz run "
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
    from clnn_ros.session import rosenv  # noqa: F401  (DDS defaults, before rclpy loads)
    if a.executor:
        os.environ["CLNN_ROS_EXECUTOR"] = a.executor
    return ring_stage(a) if a.mode == "ring-stage" else ring_composed(a)


if __name__ == "__main__":
    sys.exit(main())
