"""The graph under fuzz (scripts/fuzz_graph.py): 1,000 malformed or well-formed but impossible
messages (stale, far ahead, another graph's) on each of the seven input topics while an episode
runs (5 processes, and composed), and 1,000 task descriptions on env/task (malformed, or the
run's own again). Every subscriber refuses every one of the seven topics' messages, for the
expected reason (its content, or its tick), ignores the late descriptions, no real message is
refused (each node's refusal summary holds exactly the fuzz), and the episode equals the core's
bit for bit. Offline: every fuzz message is of its category as the nodes will receive it."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from clnn_ros.core.episode import run_episode
from clnn_ros.core.params import Params
from clnn_ros.graph.names import TASK

from test_graph import EPISODE_HANG_S

from conftest import HANG_S, free_domain_id, problem_lines

DOMAIN_ID = free_domain_id()
SCRIPTS = Path(__file__).parents[1] / "scripts"
FUZZER = SCRIPTS / "fuzz_graph.py"
# Each node's refusal summary (graph.lockstep.Refusals.summary), logged once at exit:
# "[WARN] [<time>] [<node>]: refused N messages: <topic> (<kind>) <count>, ..."
SUMMARY = re.compile(r"\[WARN\] \[[^]]*\] \[([\w.]+)\]: refused (\d+) messages: (.*)$")
PART = re.compile(r"(\S+) \((content|tick)\) (\d+)")
WELL_FORMED = {"stale_tick", "far_tick", "foreign_graph"}


def refusal_summaries(stderr: str) -> Counter:
    """(node, topic, "content" or "tick"): count, from the nodes' refusal summaries (one per
    node at most)."""
    counts, nodes = Counter(), []
    for match in filter(None, map(SUMMARY.search, stderr.splitlines())):
        node, total, parts = match.groups()
        nodes.append(node)
        found = [PART.fullmatch(part) for part in parts.split(", ")]
        assert all(found), match.group(0)
        for topic, kind, count in (part.groups() for part in found):
            counts[node, topic, kind] += int(count)
        assert sum(int(part.group(3)) for part in found) == int(total), match.group(0)
    assert len(nodes) == len(set(nodes)), f"more than one summary of a node: {sorted(nodes)}"
    return counts


def first_foreign(logged: str) -> str:
    """The topics of the trial manager's one warning of a foreign publisher (each graph topic it
    was seen publishing on)."""
    found = re.findall(r"a foreign publisher on (.+?): node 'fuzz_graph' in namespace /: the run "
                       r"goes on", logged)
    assert len(found) == 1, logged[-2000:]
    return found[0]


@pytest.mark.parametrize("nsv", [1, 2])
def test_every_fuzz_message_is_of_its_category_as_received(monkeypatch, nsv):
    """Offline (no DDS): each topic's plan of 2,000 messages made for live ticks, serialized and
    deserialized as the nodes receive them: each is refused for its content, refused for its
    tick (and fits the task, which the encoder checks too), or, on env/task, a description
    that the run refuses or one of its own task; every category of every topic is made."""
    import random
    from rclpy.serialization import deserialize_message, serialize_message
    monkeypatch.syspath_prepend(str(SCRIPTS))
    from fuzz_messages import IGNORED, STALE_FROM, TYPES, MessageMaker, judged, schedule
    p, rng = Params(nsv=nsv, max_steps=1500), random.Random(nsv)
    maker, kinds = MessageMaker(p, rng), Counter()
    for topic, plan in schedule(2000, rng).items():
        for live, category in enumerate(plan, start=STALE_FROM):
            sent = maker.make(topic, category, live)
            received = deserialize_message(serialize_message(sent), TYPES[topic])
            kind, _ = judged(topic, category, received, live, maker)
            assert kind is not None, (topic, category, received)
            kinds[topic, category, kind] += 1
    assert {(topic, kind) for topic, _, kind in kinds} == \
        {(topic, kind) for topic in TYPES if topic != TASK for kind in ("content", "tick")} | \
        {(TASK, IGNORED)}
    assert len(kinds) == sum(len(set(plan)) for plan in schedule(10, random.Random(0)).values())


@pytest.mark.ros  # starts ROS / DDS
@pytest.mark.parametrize("composed", [False, True], ids=["processes", "composed"])
def test_every_fuzz_message_is_refused_and_the_episode_equals_the_core(tmp_path, composed):
    env = {**os.environ, "ROS_DOMAIN_ID": DOMAIN_ID, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "ROS_LOG_DIR": str(tmp_path / "ros_log")}
    # 20 trials: 16,930 ticks; 14: 9,425 (5 processes tick at a quarter of the composed rate)
    seed, trials, max_steps, per_topic = 2, 20 if composed else 14, 1500, 1000
    report_path, graph_log = tmp_path / "fuzz.json", tmp_path / "graph_stderr.txt"
    # The fuzzer starts first and waits for the graph (a participant that joins a running
    # graph late is discovered late); on every tick it sees it sends 10 messages per topic, so
    # it needs 100 ticks. It may discover the graph late, likely at Fast DDS's next participant
    # announcement (every 3 s): it saw the first clock up to 2.4 s, 8,200 ticks, into a
    # composed episode, and 3.1 s, tick 2,391, into an idle 5-process one (780 ticks/s). The
    # episodes leave room for that: at least 5 s composed, 12 s in 5 processes.
    fuzzer = subprocess.Popen(
        [sys.executable, str(FUZZER), "--seed", "7", "--per-topic", str(per_topic),
         "--per-tick", "10", "--max-steps", str(max_steps), "--report", str(report_path)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    with open(graph_log, "w") as stderr:  # throttled refusal lines and the summaries
        graph = subprocess.Popen(
            [sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--no-record", "--seed",
             str(seed), "--trials", str(trials), "--max-steps", str(max_steps), "--out",
             str(tmp_path), "--allow-foreign-publishers", *(["--composed"] if composed else [])],
            env=env,
            stdout=subprocess.DEVNULL, stderr=stderr)
    try:
        deadline = time.monotonic() + EPISODE_HANG_S
        while graph.poll() is None and time.monotonic() < deadline:
            time.sleep(0.5)
        assert graph.poll() is not None, f"run_all still runs after {EPISODE_HANG_S} s"
        _, fuzz_errors = fuzzer.communicate(timeout=HANG_S)
    finally:
        graph.kill()
        fuzzer.kill()
    assert fuzzer.returncode == 0, fuzz_errors
    logged = graph_log.read_text()
    # The fuzzer is a foreign publisher: named, the run goes on (as asked) and ends tainted,
    # never "completed"; each node took the real EPISODE_END.
    assert graph.returncode == 1, logged[-2000:]
    assert problem_lines(logged) == [
        f"run_all: error: tainted: a foreign publisher on {report_topic}: node 'fuzz_graph' in "
        f"namespace /" for report_topic in [first_foreign(logged)]], logged[-2000:]
    report = json.loads(report_path.read_text())

    for topic, sent in report["sent"].items():
        assert sum(sent.values()) == per_topic, topic
        if topic == TASK:  # no tick: malformed descriptions and the run's own, all ignored
            assert report["ignored"][TASK] == sent and len(sent) >= 4, sorted(sent)
            assert not report["refusals_per_subscriber"][TASK]
            continue
        assert WELL_FORMED <= set(sent) and len(set(sent) - WELL_FORMED) >= 2, sorted(sent)
    expected = Counter({(node, topic, kind): count
                        for topic, nodes in report["subscribers"].items() for node in nodes
                        for kind, count in report["refusals_per_subscriber"][topic].items()})
    assert sum(expected.values()) == 15 * per_topic  # the 15 subscriptions of the 7 topics
    assert refusal_summaries(logged) == expected  # each one, by each subscriber, nothing else

    core = run_episode(seed, Params(trials=trials, max_steps=max_steps))
    with open(tmp_path / "trials.csv") as f:
        assert [int(row["steps"]) for row in csv.DictReader(f)] == core.steps.tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), core.final_weights)
