"""Leak check: consecutive runs leave nothing behind.

    python scripts/leak_check.py [--runs 20] [--trials 2] [--max-steps 300]

Part 1, separate processes: `--runs` runs of `python -m clnn_ros.run_all` (five nodes and the
recorder each), one after the other. After each run: no process of the run is left, no Fast DDS
shared-memory file is new in /dev/shm (the project's DDS runs over UDP), and the bag is complete.
Part 2, one process: `--runs` composed episodes (`run_all --composed`) in this Python process.
Its open file descriptors must not grow at all after the first run, and its resident memory
must not grow by more than RSS_BOUND_MB from the second run to the last.

Prints a table and one verdict line; exit status 0 if nothing leaked, 1 otherwise. Other DDS
users of the machine make /dev/shm files too; to count only this check's, give it a private
/dev/shm (tests/test_leaks.py does):
    unshare --mount sh -c 'mount -t tmpfs tmpfs /dev/shm && python scripts/leak_check.py'
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from clnn_ros.session.rosenv import processes_with_env

RSS_BOUND_MB = 20.0  # allowed resident-memory growth over the in-process runs (allocator noise)


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS in /proc/self/status")


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def fast_dds_shm_files() -> set[str]:
    return {name for name in os.listdir("/dev/shm") if "fastrtps_" in name}


def separate_runs(runs: int, episode: list[str], workdir: Path) -> list[str]:
    problems, forced = [], []
    shm_before = fast_dds_shm_files()
    for run in range(runs):
        out = workdir / f"run{run:02d}"
        started = time.monotonic()
        result = subprocess.run([sys.executable, "-m", "clnn_ros.run_all", *episode, "--out",
                                 str(out)], env={**os.environ, "CLNN_LEAK_RUN": str(out)},
                                capture_output=True, text=True, timeout=120)
        left = processes_with_env("CLNN_LEAK_RUN", str(out))
        new_shm = fast_dds_shm_files() - shm_before
        print(f"process run {run + 1:2d}: exit {result.returncode}, "
              f"{time.monotonic() - started:5.1f} s, processes left {len(left)}, "
              f"new /dev/shm files {len(new_shm)}", flush=True)
        if result.returncode != 0:
            problems.append(f"run {run + 1} exited {result.returncode}")
        if left:
            problems.append(f"run {run + 1} left processes {left}")
        if new_shm:
            problems.append(f"run {run + 1} left /dev/shm files {sorted(new_shm)}")
            shm_before |= new_shm  # report each file once
        if "did not exit" in result.stderr:
            forced.append(run + 1)
        if result.returncode != 0 or left or new_shm:
            print(f"process run {run + 1} stderr:\n{result.stderr}", file=sys.stderr, flush=True)
        if not (out / "bag" / "metadata.yaml").is_file():
            problems.append(f"run {run + 1} left no finished bag")
    if forced:  # handled (stopped, its files removed), but worth knowing
        print(f"process runs {forced}: a node did not exit within run_all's grace period and was "
              f"terminated (or, hung in native code, killed; run_all's warning says which)",
              flush=True)
    return problems


def in_process_runs(runs: int, episode: list[str], workdir: Path) -> list[str]:
    from clnn_ros import run_all
    fds, rss = [], []
    for run in range(runs):
        status = run_all.main([*episode, "--composed", "--no-record",
                               "--out", str(workdir / f"composed{run:02d}")])
        fds.append(open_fds())
        rss.append(rss_mb())
        print(f"composed run {run + 1:2d}: exit {status}, open fds {fds[-1]}, "
              f"RSS {rss[-1]:.1f} MB", flush=True)
        if status != 0:
            return [f"composed run {run + 1} exited {status}"]
    problems = []
    if max(fds) > fds[0]:
        problems.append(f"open fds grew from {fds[0]} to {max(fds)}")
    if runs > 1 and rss[-1] - rss[1] > RSS_BOUND_MB:
        problems.append(f"RSS grew {rss[-1] - rss[1]:.1f} MB (bound {RSS_BOUND_MB} MB)")
    return problems


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--trials", type=int, default=2)
    parser.add_argument("--max-steps", type=int, default=300)
    args = parser.parse_args(argv)
    episode = ["--quiet", "--seed", "1", "--trials", str(args.trials),
               "--max-steps", str(args.max_steps)]
    with tempfile.TemporaryDirectory(prefix="clnn_leak_") as tmp:
        problems = separate_runs(args.runs, episode, Path(tmp))
        problems += in_process_runs(args.runs, episode, Path(tmp))
    if problems:
        print(f"leak_check: {len(problems)} problems: " + "; ".join(problems), file=sys.stderr)
        return 1
    print(f"leak_check: {args.runs} process runs and {args.runs} composed runs left nothing "
          f"(no process, no /dev/shm file, no fd growth, RSS growth within {RSS_BOUND_MB} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
