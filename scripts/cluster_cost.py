"""What a sweep costs, measured on this machine: the batch engine's agent-steps per second on one
core, the size of a stored unit, and the arithmetic of a planned sweep (docs/CLUSTER.md).

    .venv/bin/python scripts/cluster_cost.py [--seeds 0-31] [--trials 512] [--plan-seeds 10000]
        [--plan-configs 50] [--workers 64]

An agent-step is one tick: the encoder, the network's decision, the physics and the learning
rule once (a trial's successful steps, and its failing step). The rate is measured with one numba
thread, as a cluster worker runs (one worker per CPU), in wall time and in the process's CPU
time; the plan uses the CPU-time rate (a loaded machine's wall time counts the others' work).
"""

from __future__ import annotations

import argparse
import io
import os
import time

import numba
import numpy as np

from clnn_ros.batch import run_batch
from clnn_ros.core.params import Params
from clnn_ros.core.physics import CONTINUE
from clnn_ros.reproduce.common import SEED_BLOCK, parse_seeds, run_unit

CAP = Params().max_steps  # a trial's most steps


def agent_steps(steps: np.ndarray, status: np.ndarray) -> int:
    return int(steps.sum() + (status != CONTINUE).sum())


def measure(p: Params, seeds: list[int]) -> dict:
    numba.set_num_threads(1)
    run_batch([0], Params(trials=1))  # compiled (or loaded from numba's cache) before timing
    wall, cpu = time.perf_counter(), time.process_time()
    r = run_batch(seeds, p)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    ticks = agent_steps(r.steps, r.end_status)
    return dict(ticks=ticks, wall=wall, cpu=cpu, mean=float(r.steps.mean()),
                per_trial=ticks / r.steps.size)


def unit_bytes(p: Params) -> int:
    """A stored unit of SEED_BLOCK seeds (np.savez_compressed, as the store writes it)."""
    f = io.BytesIO()
    np.savez_compressed(f, **run_unit(p, np.arange(SEED_BLOCK)))
    return f.getbuffer().nbytes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", default="0-31")
    parser.add_argument("--trials", type=int, default=512)
    parser.add_argument("--plan-seeds", type=int, default=10_000)
    parser.add_argument("--plan-configs", type=int, default=50)
    parser.add_argument("--workers", type=int, default=64, help="cluster CPUs in the plan")
    args = parser.parse_args()
    seeds = parse_seeds(args.seeds)
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    rows = {}
    for label, p in (("1 SV", Params(nsv=1, trials=args.trials)),
                     ("2 SV, edge 0.2812", Params(nsv=2, trials=args.trials,
                                                  velocity_edge=0.2812))):
        m = rows[label] = measure(p, seeds)
        print(f"{label}: {len(seeds)} seeds x {args.trials} trials = {m['ticks']:,} agent-steps "
              f"(mean {m['per_trial']:,.0f} a trial) in {m['wall']:.2f} s wall, {m['cpu']:.2f} s "
              f"CPU: {m['ticks'] / m['wall'] / 1e6:.2f} M/s wall, "
              f"{m['ticks'] / m['cpu'] / 1e6:.2f} M/s CPU")
    size = unit_bytes(Params(nsv=1, trials=args.trials))
    rate = min(m["ticks"] / m["cpu"] for m in rows.values())  # the slower encoding
    episodes = args.plan_seeds * args.plan_configs
    units = args.plan_configs * -(-args.plan_seeds // SEED_BLOCK)
    print(f"\nplan: {args.plan_seeds:,} seeds x {args.plan_configs} configurations x "
          f"{args.trials} trials = {episodes:,} episodes = {episodes * args.trials:,} trials; "
          f"{units:,} units of {SEED_BLOCK} seeds; one core: {rate / 1e6:.2f} M agent-steps/s")
    for label, per_trial in (("as measured (1 SV)", rows["1 SV"]["per_trial"]),
                             ("every trial at the cap", CAP + 0.0)):
        ticks = episodes * args.trials * per_trial
        core_s = ticks / rate
        print(f"  {label}: {per_trial:,.0f} agent-steps a trial -> {ticks:.3g} agent-steps = "
              f"{core_s:,.0f} core-s = {core_s / 3600:,.1f} core-hours; on {args.workers} "
              f"workers {core_s / args.workers / 60:,.1f} min; a unit "
              f"{SEED_BLOCK * args.trials * per_trial / rate:.1f} s")
    print(f"  store: {units:,} units x {size / 1024:.0f} KiB = {units * size / 2**30:.2f} GiB "
          f"(a unit: {SEED_BLOCK} seeds' steps, end reasons, start angles, final weights)")


if __name__ == "__main__":
    main()
