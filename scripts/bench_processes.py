"""The benchmark's runs as processes (scripts/benchmark_graph.py): the graph, started as run_all
starts it but with the benchmark's instrumented node entry (bench_node.py), and the raw ring."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from bench_settings import (OWN_TIME_ROLES, REPO, ROLES, RUN_TIMEOUT_S, SEED,
                            TEARDOWN_GRACE_S)
from clnn_ros.session import rosenv

NODE_ENTRY = REPO / "scripts" / "bench_node.py"
BENCHMARK = REPO / "scripts" / "benchmark_graph.py"


def child_env(**extra) -> dict:
    env = dict(os.environ)
    env.update({k: str(v) for k, v in extra.items()})
    return env


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
        # Fast DDS's shared memory, as rmw_fastrtps adds it under LOCALHOST to a profile of the
        # user's own (here the project's subnet profile: its lease, heartbeat and log): the
        # project's default transport before 2026-12-05, measured beside today's UDP.
        self.shm_profile = work / "shm_profile.xml"
        self.shm_profile.write_text(rosenv.SUBNET_PROFILE.read_text())

    def env(self, executor: str, transport: str = "udp") -> dict:
        """The environment of a run's processes: rosenv's defaults (UDP on loopback), or
        (`transport` "shm") shared memory and UDP."""
        if transport == "udp":
            return child_env(CLNN_ROS_EXECUTOR=executor)
        return child_env(CLNN_ROS_EXECUTOR=executor, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                         FASTRTPS_DEFAULT_PROFILES_FILE=self.shm_profile)

    def out_dir(self, name: str) -> Path:
        return self.work / f"{name}_{time.monotonic_ns()}"

    def graph_run(self, layout: str, executor: str, trials: int,
                  profile: Path | None = None, sim_time_everywhere: bool = False,
                  transport: str = "udp") -> dict:
        """One episode of the graph without the recorder, as `run_all --quiet --no-record`
        runs it (the run's values and node arguments from clnn_ros.graph.run; the trial manager
        started last); its summary.json, with the per-tick latencies in microseconds
        ("latency_us") unless profiled (`profile`: a file for the composed run, a folder of
        ROLE.prof for the node processes). `sim_time_everywhere`: OWN_TIME_ROLES started with
        use_sim_time true as well. `transport`: Bench.env's."""
        from clnn_ros.graph.run import DEMO, node_arguments, run_values, write_params

        out = self.out_dir(f"graph_{layout}_{executor}")
        out.mkdir()
        values, _ = run_values(DEMO, flags=dict(seed=SEED, trials=trials, progress=False,
                                                simulator="cartpole"))
        values["out_dir"] = str(out)
        ticks_file = out / "ticks.json"
        timing = [] if profile else ["--ticks-file", str(ticks_file)]
        entry = [sys.executable, str(NODE_ENTRY)]
        if layout == "composed":
            values_file = out / "values.json"
            values_file.write_text(json.dumps(values))
            commands = [entry + ["composed", "--values", str(values_file), *timing]
                        + (["--profile", str(profile)] if profile else [])
                        + (["--sim-time-everywhere"] if sim_time_everywhere else [])]
        else:
            arguments = node_arguments(write_params(out / "params.yaml", values), "/")
            commands = [entry + [role, *(timing if role == "trial_manager" else []),
                                 *(["--profile", str(profile / f"{role}.prof")] if profile
                                   else []), *arguments,
                                 *(["-p", "use_sim_time:=true"]
                                   if sim_time_everywhere and role in OWN_TIME_ROLES else [])]
                        for role in ROLES]
        run_group(commands, self.env(executor, transport), RUN_TIMEOUT_S)
        summary = json.loads((out / "summary.json").read_text())
        if summary["exit_reason"] != "completed":
            raise RuntimeError(f"graph run did not complete: {summary}")
        if not profile:
            record = json.loads(ticks_file.read_text())
            published, completed = record["published"], record["completed"]
            if len(published) != summary["ticks"] or len(completed) != summary["ticks"]:
                raise RuntimeError(f"tick timing: {len(published)} clocks, {len(completed)} "
                                   f"completions for {summary['ticks']} ticks")
            summary["latency_us"] = [(c - p) / 1e3 for p, c in zip(published, completed)]
        return summary

    def ring_rate(self, layout: str, executor: str, msgs: str, transport: str = "udp") -> dict:
        me = [sys.executable, str(BENCHMARK)]
        common = ["--ticks", str(self.sizes["ring_ticks"][layout, executor]), "--msgs", msgs]
        if layout == "composed":
            commands = [me + ["ring-composed", *common]]
        else:  # the trial manager last, as run_all starts it
            commands = [me + ["ring-stage", "--role", role, *common] for role in ROLES]
        return self.run_ring(commands, self.env(executor, transport))

    def run_ring(self, commands: list[list[str]], env: dict) -> dict:
        """Run the ring's processes; the trial manager's (the last command's) RING_RESULT. A
        ring process that has not exited TEARDOWN_GRACE_S after the result is in (seen:
        rclpy/Fast DDS teardown hanging once in a while; the teardown is not measured) is
        killed and counted in self.forced_ring_exits."""
        base = self.out_dir("ring")
        outs = [base.with_name(f"{base.name}_{i}.out") for i in range(len(commands))]
        errs = [path.with_suffix(".err") for path in outs]
        procs = []

        def kill(p: subprocess.Popen) -> None:
            kill_group(p)
            p.wait()

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
