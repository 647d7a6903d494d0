"""What a fixed set of forces allows on a MuJoCo balancing task, the encoding aside (issue 46):
a linear controller (LQR on the task's own model, linearized at the upright state by finite
differences of whole control steps) played continuous, and quantized to the nearest of a few
forces, from Gymnasium's own starts. If the quantized controller holds the task, the forces
suffice and what a table policy lacks is the switching surface: a linear function of all the
state, which a 1-hot encoding of each variable's intervals can only approximate.

    .venv/bin/python scripts/linear_controller_probe.py gymnasium:InvertedDoublePendulum-v5 \
        --levels=-0.3,0,0.3 --levels=-0.6,-0.3,0,0.3,0.6 --csv out/linear.csv
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import gymnasium
import mujoco
import numpy as np

from clnn_ros.cli import OneLineArgumentParser
from clnn_ros.reproduce.common import parse_seeds
from clnn_ros.tasks.gymnasium_task import env_id

RICCATI_ITERATIONS = 20_000
STATE_COST, FORCE_COST = 1.0, 1.0  # LQR's weights: every qpos and qvel alike, the control
FD_EPS = 1e-6


def linearized(env) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of one control step (frame_skip MuJoCo steps) at the upright state, qpos then qvel,
    by central differences on a copy of the task's data."""
    model = env.unwrapped.model
    data = mujoco.MjData(model)
    frame_skip = env.unwrapped.frame_skip

    def step(x: np.ndarray, force: float) -> np.ndarray:
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = x[:model.nq], x[model.nq:]
        data.ctrl[:] = force
        for _ in range(frame_skip):
            mujoco.mj_step(model, data)
        return np.concatenate([data.qpos, data.qvel])

    n = model.nq + model.nv
    unit = np.eye(n) * FD_EPS
    a = np.stack([(step(unit[i], 0.0) - step(-unit[i], 0.0)) / (2 * FD_EPS) for i in range(n)], 1)
    b = ((step(np.zeros(n), FD_EPS) - step(np.zeros(n), -FD_EPS)) / (2 * FD_EPS))[:, None]
    return a, b


def lqr_gain(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The discrete LQR gain K (control = -K x), the Riccati equation iterated to its fixed
    point."""
    q, r = STATE_COST * np.eye(a.shape[0]), FORCE_COST * np.eye(b.shape[1])
    p = q
    for _ in range(RICCATI_ITERATIONS):
        gain = np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)
        p = q + a.T @ p @ (a - b @ gain)
    return gain


def play(env, policy, seeds: list[int]) -> tuple[float, float]:
    """Mean return and mean steps of one episode from each seed's reset."""
    data, returns, steps = env.unwrapped.data, [], []
    for seed in seeds:
        env.reset(seed=seed)
        total, n, done = 0.0, 0, False
        while not done:
            force = policy(np.concatenate([data.qpos, data.qvel]))
            _, reward, terminated, truncated, _ = env.step(
                np.array([force], dtype=env.action_space.dtype))
            total, n, done = total + reward, n + 1, terminated or truncated
        returns.append(total)
        steps.append(n)
    return float(np.mean(returns)), float(np.mean(steps))


def main(argv=None) -> int:
    parser = OneLineArgumentParser(prog="linear_controller_probe.py", name="linear_controller_probe",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("task", help="gymnasium:ID of a MuJoCo task with one actuator")
    parser.add_argument("--levels", action="append", default=[],
                        help="a set of forces, e.g. --levels=-1,0,1 (repeatable)")
    parser.add_argument("--seeds", default="128-137", help="the resets' seeds (selection: 128-255)")
    parser.add_argument("--csv", type=Path)
    args = parser.parse_args(argv)
    try:
        env = gymnasium.make(env_id(args.task))
        seeds = parse_seeds(args.seeds)
        level_sets = [np.array([float(v) for v in text.split(",")]) for text in args.levels]
    except (gymnasium.error.Error, ValueError) as error:
        parser.error(str(error))
    if not hasattr(env.unwrapped, "frame_skip") or env.action_space.shape != (1,):
        parser.error(f"{args.task} is not a MuJoCo task with one actuator")
    low, high = float(env.action_space.low[0]), float(env.action_space.high[0])
    gain = lqr_gain(*linearized(env))[0]

    def linear(x: np.ndarray) -> float:
        return float(np.clip(-gain @ x, low, high))
    rows = [("linear (continuous, clipped)", "", *play(env, linear, seeds))]
    for levels in level_sets:
        rows.append(("linear, nearest force", " ".join(f"{v:g}" for v in levels), *play(
            env, lambda x, lv=levels: float(lv[np.argmin(abs(lv - linear(x)))]), seeds)))
    print(f"{args.task}: LQR gain over qpos, qvel: {np.round(gain, 3).tolist()}; "
          f"{len(seeds)} episodes each, threshold {env.spec.reward_threshold}")
    for policy, levels, mean_return, mean_steps in rows:
        print(f"  {policy:30s} {levels:22s} mean return {mean_return:9.1f}  "
              f"mean steps {mean_steps:7.1f}")
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with open(args.csv, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["task", "policy", "forces", "mean_return", "mean_steps", "episodes",
                             "gain"])
            for row in rows:
                writer.writerow([args.task, *row, len(seeds), " ".join(f"{g:.4f}" for g in gain)])
    return 0


if __name__ == "__main__":
    sys.exit(main())
