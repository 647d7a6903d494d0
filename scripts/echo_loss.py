"""What a stock `ros2 topic echo` (ros2cli, not on PyPI: give its `ros2` command) receives of the
graph's env/observation at its default QoS, for the README's figure (issue 47): the graph
(`run_all --no-record`, seed 0) runs unpaced or at `--rate HZ`; echo is started before the graph
(with no publisher to match, its default profile stays best effort, depth 5) or once the graph
is ticking (then it matches the graph's publisher: reliable, depth 5). Echo runs as a user runs
it: full messages, its own Fast DDS defaults, discovery on loopback.

    ROS_DOMAIN_ID=N python scripts/echo_loss.py --ros2 PATH/TO/ros2 [--trials 20] [--rate 0]

Prints one Markdown row per way of starting echo: the graph's ticks/s, the ticks echo printed
of those sent while it listened, and the share lost.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from clnn_ros.session.rosenv import PROFILES_FILE, RANGE

TOPIC, TYPE = "/env/observation", "clnn_ros_msgs/msg/Observation"
SUBSCRIBED_S = 5.0  # for echo, started first, to be up before the graph's first tick


def measure(ros2: str, trials: int, rate: float, echo_first: bool, workdir: Path) -> dict:
    out = workdir / ("echo_first" if echo_first else "graph_first")
    echo_env = {**os.environ, RANGE: os.environ.get(RANGE, "LOCALHOST")}
    echo_env.pop(PROFILES_FILE, None)  # a stock tool: Fast DDS's own defaults
    echo_cmd = [ros2, "topic", "echo", "--no-daemon", TOPIC, TYPE]
    graph_cmd = [sys.executable, "-m", "clnn_ros.run_all", "--quiet", "--no-record", "--seed",
                 "0", "--trials", str(trials), "--out", str(out)] + \
        (["--rate", f"{rate:g}"] if rate else [])
    printed = workdir / "echo.txt"
    with open(printed, "w") as sink:
        echo = subprocess.Popen(echo_cmd, stdout=sink, stderr=subprocess.DEVNULL,
                                env=echo_env) if echo_first else None
        if echo_first:
            time.sleep(SUBSCRIBED_S)
        graph = subprocess.Popen(graph_cmd, stdout=subprocess.DEVNULL)
        if not echo_first:  # once the graph ticks: its first trial written
            while not (out / "trials.csv").exists() and graph.poll() is None:
                time.sleep(0.05)
            echo = subprocess.Popen(echo_cmd, stdout=sink, stderr=subprocess.DEVNULL,
                                    env=echo_env)
        graph.wait()
        time.sleep(2.0)  # what echo still has in flight
        echo.send_signal(signal.SIGINT)
        echo.wait(timeout=60)
    summary = json.loads((out / "summary.json").read_text())
    ticks = {int(t) for t in re.findall(r"^tick: (\d+)$", printed.read_text(), re.M)}
    sent = summary["ticks"] - min(ticks) if ticks else 0  # from the first it printed
    return dict(way="echo started before the graph (best effort, depth 5)" if echo_first
                else "echo started once the graph ticks (reliable, depth 5)",
                rate=summary["ticks_per_s"], received=len(ticks), sent=sent,
                lost=1 - len(ticks) / sent if sent else float("nan"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ros2", required=True, help="the ros2 command (ros2cli)")
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--rate", type=float, default=0.0, help="ticks/s (0: unpaced)")
    args = parser.parse_args()
    print("| how echo was started | graph ticks/s | ticks printed / sent | lost |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory(prefix="echo_loss_") as tmp:
        for echo_first in (True, False):
            row = measure(args.ros2, args.trials, args.rate, echo_first, Path(tmp))
            print(f"| {row['way']} | {row['rate']:.0f} | {row['received']:,} / {row['sent']:,} "
                  f"| {100 * row['lost']:.1f} % |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
