"""The graph under fuzz (scripts/fuzz_graph.py): 1,000 malformed or hostile messages on each of
the seven input topics while an episode runs (5 processes, and composed). Every subscriber
refuses every one of them, each with a logged reason of the expected kind (its content, or a
sender that is not the topic's publisher), no real message is refused, and the episode equals
the core's bit for bit."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from clnn_ros.core.episode import run_episode
from clnn_ros.core.params import Params

DOMAIN_ID = str(90 + os.getpid() % 10)
FUZZER = Path(__file__).parents[1] / "scripts" / "fuzz_graph.py"
# GraphNode.refuse: "[ERROR] [<time>] [<node>]: refused <topic> tick <tick>: <reason>"
REFUSAL = re.compile(r"\[(\w+)\]: refused (\S+) tick \S+: (.*)$")
UNKNOWN_PUBLISHER = "from an unknown publisher"
WELL_FORMED = {"wrong_tick", "duplicate_tick", "reordered_tick", "hostile_next_tick"}


def refusals(stderr: str) -> Counter:
    """(node, topic, "publisher" or "content"): refusals logged."""
    counts = Counter()
    for match in filter(None, map(REFUSAL.search, stderr.splitlines())):
        node, topic, reason = match.groups()
        counts[node, topic, "publisher" if UNKNOWN_PUBLISHER in reason else "content"] += 1
    return counts


@pytest.mark.parametrize("composed", [False, True], ids=["processes", "composed"])
def test_every_fuzz_message_is_refused_and_the_episode_equals_the_core(tmp_path, composed):
    env = {**os.environ, "ROS_DOMAIN_ID": DOMAIN_ID, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "ROS_LOG_DIR": str(tmp_path / "ros_log")}
    seed, trials, max_steps, per_topic = 2, 16, 1500, 1000
    report_path, graph_log = tmp_path / "fuzz.json", tmp_path / "graph_stderr.txt"
    # The fuzzer starts first and waits for the graph (a participant that joins a running
    # graph late is discovered late); on every tick it sees it sends 10 messages per topic
    # (it sees only some ticks of a composed graph: 1,000 per topic must fit in the episode).
    fuzzer = subprocess.Popen(
        [sys.executable, str(FUZZER), "--seed", "7", "--per-topic", str(per_topic),
         "--per-tick", "10", "--max-steps", str(max_steps), "--report", str(report_path)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        with open(graph_log, "w") as stderr:  # 15,000 refusal lines: a file, not a pipe
            graph = subprocess.run(
                [sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--no-record", "--seed",
                 str(seed), "--trials", str(trials), "--max-steps", str(max_steps), "--out",
                 str(tmp_path), *(["--composed"] if composed else [])], env=env,
                stdout=subprocess.PIPE, stderr=stderr, text=True, timeout=240)
        _, fuzz_errors = fuzzer.communicate(timeout=60)
    finally:
        fuzzer.kill()
    assert fuzzer.returncode == 0, fuzz_errors
    logged = graph_log.read_text()
    assert graph.returncode == 0, logged[-2000:]
    report = json.loads(report_path.read_text())

    for topic, sent in report["sent"].items():
        assert sum(sent.values()) == per_topic, topic
        assert WELL_FORMED < set(sent) and len(set(sent) - WELL_FORMED) >= 2, sorted(sent)
    expected = Counter({(node, topic, kind): count
                        for topic, nodes in report["subscribers"].items() for node in nodes
                        for kind, count in report["refusals_per_subscriber"][topic].items()})
    assert refusals(logged) == expected  # each one, by each subscriber, and nothing else

    core = run_episode(seed, Params(trials=trials, max_steps=max_steps))
    with open(tmp_path / "trials.csv") as f:
        assert [int(row["steps"]) for row in csv.DictReader(f)] == core.steps.tolist()
    np.testing.assert_array_equal(np.load(tmp_path / "final_weights.npy"), core.final_weights)
