"""Benchmark of the model itself (no ROS): agent-steps per second of the numba batch engine, of the
pure-Python reference core and of Gymnasium's CartPole-v1 environment alone (no agent), the
RLN agent on Gymnasium's other tasks beside their own step, all measured in this one run, plus the wall time of the paper's full 1-SV set (32 seeds x 512 trials)
with the compile time reported separately.

    python scripts/benchmark_core.py [--out docs/benchmark_core.md] [--against REV] [--threads 1,2]

--against REV also times the batch engine of an earlier commit (its whole clnn_ros package, as
`git archive` gives it) on the same full sets, in the same run: each engine in fresh processes,
taking turns, so that both see the same machine load.

--threads: the numba thread counts (NUMBA_NUM_THREADS) each engine runs the full sets with, in
the same turns; one thread is the engine's speed per core, 1 and 2 give its scaling from one
thread to two (default 1,2).

With one thread among --threads, it also measures the physics floor: the core's physics step
alone, compiled as the engine compiles it, with 1 to 8 cart-poles stepped in turn, and libm's
sin + cos pair (what a tick costs at least in any engine that equals the core).

An agent-step is one tick: encode, infer, tag, physics step, reward and update. Gymnasium's
figure is an environment step alone, with a fixed action, as a yardstick for "how fast can a
Python cart-pole go at all".
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path


SEEDS, TRIALS = 32, 512  # the paper's full set
CORE_STEPS = 200_000  # enough for a stable rate of the slow reference
GYM_STEPS = 200_000
REPEATS = 3  # best of, for the batch engine's full set
THREADS = (1, 2)
FLOOR_STEPS = 20_000_000  # physics steps per floor measurement
LANES = (1, 2, 4, 8)  # independent cart-poles stepped in turn
TASK_STEPS = 20_000  # steps per Gymnasium task, of the learner and of the environment alone


def compile_seconds() -> float:
    """First call in a fresh process with an empty numba cache: the compile cost."""
    code = ("import time; t = time.perf_counter();"
            "from clnn_ros.batch import run_batch; from clnn_ros.core.params import Params;"
            "run_batch([0], Params(trials=1, max_steps=1));"
            "print(time.perf_counter() - t)")
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        out = subprocess.run([sys.executable, "-c", code], env=env, check=True, text=True,
                             capture_output=True).stdout
    return float(out.split()[-1])


def full_set_seconds(package_root: Path, nsv: int, threads: int) -> tuple[float, int]:
    """(wall s, ticks) of one full set by the batch engine of the clnn_ros package in
    package_root on `threads` numba threads, in a fresh process, once its compiled code is
    loaded."""
    code = ("import sys, time; from clnn_ros.batch import run_batch;"
            "from clnn_ros.core.params import Params;"
            f"p = Params(nsv={nsv}, trials={TRIALS});"
            "run_batch([0], p.replace(trials=1, max_steps=1));"
            f"t = time.perf_counter(); r = run_batch(range({SEEDS}), p);"
            "print(time.perf_counter() - t, r.steps.sum() + r.steps.size)")
    env = {**os.environ, "PYTHONPATH": str(package_root), "NUMBA_NUM_THREADS": str(threads)}
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=package_root, check=True,
                         text=True, capture_output=True).stdout.split()
    return float(out[-2]), int(out[-1])  # the failing step is a tick too


def best_full_sets(roots: dict[str, Path], nsv: int,
                   threads: tuple[int, ...]) -> dict[tuple[str, int], tuple[float, int]]:
    """Best of REPEATS (wall s, ticks) of each engine on each thread count, keyed by (engine,
    threads), the engines and thread counts taking turns."""
    best = {(name, n): (float("inf"), 0) for n in threads for name in roots}
    for _ in range(REPEATS):
        for key in best:
            best[key] = min(best[key], full_set_seconds(roots[key[0]], nsv, key[1]))
    return best


def checkout(rev: str, into: Path) -> Path:
    """The clnn_ros package of commit `rev`, unpacked under `into`."""
    root = Path(__file__).resolve().parents[1]
    archive = subprocess.run(["git", "archive", rev, "clnn_ros"], cwd=root, check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into


def core_rate() -> float:
    from clnn_ros.core.episode import run_episode
    from clnn_ros.core.params import Params

    ticks, trials, start = 0, 8, time.perf_counter()
    while ticks < CORE_STEPS:
        result = run_episode(0, Params(trials=trials))
        ticks += int(result.steps.sum() + result.steps.size)
        trials *= 2
    return ticks / (time.perf_counter() - start)


def gymnasium_rate() -> float:
    import gymnasium

    env = gymnasium.make("CartPole-v1").unwrapped  # no wrappers: the bare physics step
    env.reset(seed=0)
    start = time.perf_counter()
    for k in range(GYM_STEPS):
        _, _, terminated, _, _ = env.step(k & 1)
        if terminated:
            env.reset()
    return GYM_STEPS / (time.perf_counter() - start)


def task_rates() -> list[tuple[str, float, float]]:
    """(task, the learner's agent-steps/s, Gymnasium's own steps/s) for each Gymnasium task the
    project knows: the pure core learning in the task's environment (one process, its first
    encoding), and the same environment stepped alone with its actions in turn (resets
    included): the floor of any learner that steps Gymnasium's own code."""
    from clnn_ros.batch import COMPILED_KERNELS
    from clnn_ros.core.task_episode import run_task_episode
    from clnn_ros.tasks.gymnasium_task import KNOWN, make, task_params

    rates = []
    for identifier in KNOWN:
        task, env = make(f"gymnasium:{identifier}")
        p = task_params(task)
        run_task_episode(0, p.replace(trials=1), task, env, kernels=COMPILED_KERNELS)  # compiled
        ticks, trials, start = 0, 1, time.perf_counter()
        while ticks < TASK_STEPS:
            ticks += int(run_task_episode(0, p.replace(trials=trials), task, env,
                                          kernels=COMPILED_KERNELS).steps.sum())
            trials *= 2
        learner = ticks / (time.perf_counter() - start)
        env.reset(0)
        start = time.perf_counter()
        for k in range(TASK_STEPS):
            _, _, terminated, truncated = env.step(k % len(task.actions))
            if terminated or truncated:
                env.reset(None)
        rates.append((identifier, learner, TASK_STEPS / (time.perf_counter() - start)))
    return rates


def task_lines(rates: list[tuple[str, float, float]]) -> list[str]:
    return ["Gymnasium's tasks (issue 45): the RLN agent learning in the task's own "
            "environment as `clnn-reproduce learn --task` runs it (the core ticking in Python, "
            "the rule's costly functions compiled; one process, the task's first encoding), "
            "beside that environment's own step alone (its actions in turn, resets included): "
            "the floor of any learner that steps Gymnasium's code.", "",
            "| task | learner agent-steps/s | Gymnasium env.step alone | learner / env.step |",
            "|---|---:|---:|---:|",
            *[f"| {task} | {learner:,.0f} | {alone:,.0f} | {learner / alone:.2f} |"
              for task, learner, alone in rates], ""]


def physics_floor() -> tuple[float, dict[int, float]]:
    """(ns per sin + cos pair of libm, {lanes: ns per physics step}), one thread, best of
    REPEATS: the core's cartpole_step compiled as the engine compiles it, `lanes` cart-poles
    stepped in turn, pushed towards their lean, each restarted where it fails (its angle stays
    within the limit, as in an episode). No agent: what a tick costs at least, in any engine
    that keeps the core's bits (they pin libm's sin and cos)."""
    import math

    import numba
    import numpy as np

    from clnn_ros import batch  # noqa: F401  (registers the core's functions with numba)
    from clnn_ros.core.params import Params
    from clnn_ros.core.physics import CONTINUE, cartpole_step, physics_constants

    @numba.njit(error_model="numpy")
    def sin_cos(n):
        total = 0.0
        for i in range(n):
            angle = 0.1 + i * 1e-9
            total += math.sin(angle) + math.cos(angle)
        return total

    @numba.njit(error_model="numpy")
    def steps(n, constants, lanes):
        starts = np.linspace(-6.0, 6.0, lanes)  # degrees
        state = np.zeros((lanes, 4))
        state[:, 2] = starts
        for _ in range(n):
            for j in range(lanes):
                x, x_dot, theta, theta_dot, status = cartpole_step(
                    state[j, 0], state[j, 1], state[j, 2], state[j, 3],
                    10.0 if state[j, 2] > 0 else -10.0, constants)  # about 1,100 steps a trial
                if status != CONTINUE:
                    x, x_dot, theta, theta_dot = 0.0, 0.0, starts[j], 0.0
                state[j, 0], state[j, 1], state[j, 2], state[j, 3] = x, x_dot, theta, theta_dot
        return state

    def best_ns(run, count: int) -> float:
        run()  # compiled
        best = float("inf")
        for _ in range(REPEATS):
            start = time.perf_counter()
            run()
            best = min(best, time.perf_counter() - start)
        return best / count * 1e9

    constants = physics_constants(Params())
    pair = best_ns(lambda: sin_cos(FLOOR_STEPS), FLOOR_STEPS)
    return pair, {lanes: best_ns(lambda lanes=lanes: steps(FLOOR_STEPS // lanes, constants, lanes),
                                 FLOOR_STEPS // lanes * lanes) for lanes in LANES}


def floor_lines(pair_ns: float, step_ns: dict[int, float], sets: dict, rev: str) -> list[str]:
    """What the physics alone costs, beside this engine's tick and issue 24's target (2x the
    engine of `rev` per core, one thread)."""
    lines = ["The physics floor, same run (one thread, best of "
             f"{REPEATS}): the core's `cartpole_step` compiled as the engine compiles it, "
             "several cart-poles stepped in turn (no agent; each restarted where it fails), "
             f"and libm's sin + cos pair alone: **{pair_ns:.1f} ns** a pair. The core's bits pin "
             "libm's sin and cos, so no engine that equals the core ticks faster than its "
             "physics step.", "",
             "| lanes | ns per physics step |", "|---:|---:|",
             *[f"| {lanes} | {ns:.1f} |" for lanes, ns in step_ns.items()], ""]
    if rev:
        for nsv, best in sets.items():
            (wall, ticks), (wall_then, _) = best["this", 1], best[rev, 1]
            lines.append(f"* {nsv} SV, one thread: this engine {wall / ticks * 1e9:.1f} ns a "
                         f"tick; 2x {rev}'s is {wall_then / ticks / 2 * 1e9:.1f} ns a tick, "
                         f"against {min(step_ns.values()):.1f} ns for the physics step alone.")
        lines.append("")
    return lines


def comparison(sets: dict, rev: str, threads: tuple[int, ...]) -> list[str]:
    """The markdown lines that set this engine's full-set times beside those of commit `rev`."""
    lines = [f"This engine and the batch engine of commit `{rev}`, the same full sets in the same "
             f"run (fresh processes taking turns, best of {REPEATS} each); speed-up: {rev}'s "
             f"time over this engine's, on as many threads:",
             "",
             f"| set | threads | this engine | {rev} | speed-up | same ticks |",
             "|---|---:|---:|---:|---:|---|"]
    for nsv, best in sets.items():
        for n in threads:
            (wall, ticks), (wall_then, ticks_then) = best["this", n], best[rev, n]
            same = "yes" if ticks == ticks_then else f"no: {ticks:,} vs {ticks_then:,}"
            lines.append(f"| {nsv} SV | {n} | {wall:.2f} s | {wall_then:.2f} s | "
                         f"**{wall_then / wall:.2f}** | {same} |")
    return [*lines, ""]


def scaling(sets: dict, names: list[str], threads: tuple[int, ...]) -> list[str]:
    """The markdown lines of each engine's speed-up from one thread to the most threads."""
    if len(threads) < 2 or 1 not in threads:
        return []
    most = max(threads)
    heads = ["this engine" if name == "this" else name for name in names]
    lines = [f"From 1 thread to {most} (the one-thread time over the {most}-thread time, same "
             f"run):", "", "| set | " + " | ".join(heads) + " |", "|---|" + "---:|" * len(names)]
    for nsv, best in sets.items():
        lines.append(f"| {nsv} SV | " + " | ".join(
            f"{best[name, 1][0] / best[name, most][0]:.2f}" for name in names) + " |")
    return [*lines, ""]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/benchmark_core.md"))
    parser.add_argument("--against", metavar="REV",
                        help="also time the batch engine of this earlier commit")
    parser.add_argument("--threads", default=",".join(map(str, THREADS)), metavar="N,N",
                        help="numba thread counts to run the full sets with (default %(default)s)")
    args = parser.parse_args()
    try:
        threads = tuple(sorted({int(n) for n in args.threads.split(",")}))
    except ValueError:
        threads = ()
    if not threads or min(threads) < 1:
        parser.error(f"--threads: positive integers separated by commas, got {args.threads!r}")

    load = os.getloadavg()[0]  # others' processes share the cores: say how busy they were
    with tempfile.TemporaryDirectory() as earlier:
        roots = {"this": Path(__file__).resolve().parents[1]}
        if args.against:
            try:
                roots[args.against] = checkout(args.against, Path(earlier))
            except subprocess.CalledProcessError as error:
                parser.error(f"--against {args.against}: {error.stderr.decode().strip()}")
        compile_s = compile_seconds()
        sets = {nsv: best_full_sets(roots, nsv, threads) for nsv in (1, 2)}
    most = max(threads)
    (wall_1sv, ticks_1sv), (wall_2sv, ticks_2sv) = sets[1]["this", most], sets[2]["this", most]
    core = core_rate()
    gym = gymnasium_rate()
    pair_ns, step_ns = physics_floor()
    tasks = task_rates()
    rows = []
    for n in threads:
        for nsv in (1, 2):
            wall, ticks = sets[nsv]["this", n]
            rows.append((f"batch engine (numba, {n} thread{'s' if n > 1 else ''}), {nsv} SV",
                         f"{ticks / wall:,.0f}", f"{ticks / wall / gym:,.1f}"))
    rows += [
        ("reference core (pure Python + numpy), 1 SV", f"{core:,.0f}", f"{core / gym:,.2f}"),
        ("Gymnasium CartPole-v1 env.step alone", f"{gym:,.0f}", "1.0"),
    ]
    text = "\n".join([
        "# Benchmark: the model without ROS",
        "",
        f"Generated by `python scripts/benchmark_core.py"
        f"{' --against ' + args.against if args.against else ''}"
        f"{' --threads ' + args.threads if threads != THREADS else ''}` on {platform.node()} "
        f"({os.cpu_count()} cores, Python {platform.python_version()}, load average {load:.1f} "
        f"at the start), all rates measured in one run.",
        "",
        "| path | agent-steps/s | vs Gymnasium env.step |",
        "|---|---:|---:|",
        *[f"| {a} | {b} | {c} |" for a, b, c in rows],
        "",
        f"* Full 1-SV set, {SEEDS} seeds x {TRIALS} trials ({ticks_1sv:,} ticks): "
        f"**{wall_1sv:.2f} s** wall on {most} thread{'s' if most > 1 else ''} (best of "
        f"{REPEATS}; target <= 3 s).",
        f"* Full 2-SV set, literal velocity edge ({ticks_2sv:,} ticks): {wall_2sv:.2f} s wall.",
        f"* Numba compile time, paid once (then cached on disk): {compile_s:.1f} s.",
        "",
        *(comparison(sets, args.against, threads) if args.against else []),
        *scaling(sets, list(roots), threads),
        *(floor_lines(pair_ns, step_ns, sets, args.against) if 1 in threads else []),
        *task_lines(tasks),
    ])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
