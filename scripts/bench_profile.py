"""Where the graph's time goes (scripts/benchmark_graph.py): cProfile runs of the graph (through
bench_node.py), their exclusive time in categories (executor, TimeSource, serialization, node
work, core model), and serialization alone."""

from __future__ import annotations

import pstats
import time
from pathlib import Path

from bench_ring import ring_messages

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


def profile_composed(bench) -> tuple[pstats.Stats, dict]:
    prof = bench.work / "composed.prof"
    summary = bench.graph_run("composed", "events", bench.sizes["profile_trials"], profile=prof)
    return pstats.Stats(str(prof)), summary


def profile_separate(bench) -> tuple[dict, dict]:
    profiles = bench.work / "node_profiles"
    profiles.mkdir()
    summary = bench.graph_run("separate", "events", bench.sizes["profile_trials"],
                              profile=profiles)
    found = {p.stem: pstats.Stats(str(p)) for p in sorted(profiles.glob("*.prof"))}
    if not found:
        raise RuntimeError("no node process wrote a profile (bench_node.py --profile)")
    return found, summary


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
