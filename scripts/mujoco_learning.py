"""Does the unchanged agent learn on a cart-pole simulated by MuJoCo, as it does on the core's own
physics? One experiment: the pure core driving the MuJoCo plant
(`run_episode(seed, p, env_factory=MujocoCartPole)`, seeds in parallel processes) beside the
batch engine on the core's physics with the same constants, on the same seeds; and how closely
the plant follows the core's physics step by step. Writes docs/MUJOCO.md and
docs/data/mujoco_learning.csv.

    .venv/bin/python scripts/mujoco_learning.py

The settings below are the whole experiment; change them here.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from clnn_ros.batch import run_batch
from clnn_ros.core.episode import run_episode
from clnn_ros.core.physics import GYM_PHYSICS, gym_matched_params
from clnn_ros.tasks.cartpole.mujoco_cartpole import MujocoCartPole
from clnn_ros.core.params import params_from_strings
from clnn_ros.core.physics import CartPole, at_rest
from clnn_ros.core.presets import preset_values
from clnn_ros.reproduce.common import END_REASONS, md_table, write_csv

# ------------------------------------------------------------------------------------------------
# Settings
# ------------------------------------------------------------------------------------------------
PRESET = "gymnasium"  # the agent's encoder and rule settings (its physics values: see below)
SEEDS = range(16)
# The pure core runs about 5,000 agent-steps/s a process; learning to the 10,000-step cap takes
# some 30 million steps on 16 seeds x 256 trials (the batch engine's count): hours. A 2,000-step
# cap and 192 trials make about 5 million, some 10 minutes in 2 processes, and learning settles
# (the batch engine at this cap: every seed at the cap by trial 192).
TRIALS = 192
MAX_STEPS = 2_000
WORKERS = 2  # the machine's cores; each process runs whole seeds
LAST = 64  # "last-64 mean": each seed's mean over its last 64 trials, after learning settled
CONVERGED = 0.9  # a seed converged: last-64 mean >= 90 % of the cap (9,000 at a 10,000 cap)
STUCK = 0.1  # a seed stuck: last-64 mean below 10 % of the cap (1,000 at a 10,000 cap)
# Context, batch engine alone (seconds): the same episode on many seeds (how far 16 seeds'
# counts scatter by sampling alone), and the preset's own episode (trials, cap) on SEEDS.
CONTEXT_SEEDS = range(128)
FULL_TRIALS, FULL_MAX_STEPS = 256, 10_000

# Plant against the core's physics: one fixed action sequence, replayed open loop on each, from
# the pole at rest at AGREEMENT_ANGLE_DEG. The sequence is what a simple balancing rule (push
# toward theta + LEAD_S theta_dot) chose on the MuJoCo plant (in closed loop it keeps the pole
# within 1 deg and the cart within 3 cm for 500 steps).
AGREEMENT_ANGLE_DEG = 1.0
TEST_STEPS = 20  # the horizon over which tests/test_mujoco_env.py bounds the difference
AGREEMENT_STEPS = (TEST_STEPS, 50, 200, 500)
LEAD_S = 0.1
# A yardstick of what a small model error does over the same steps: gravity 9.81 instead of 9.8.
YARDSTICK_GRAVITY = 9.81

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "MUJOCO.md"
CSV = ROOT / "docs" / "data" / "mujoco_learning.csv"
STATE_COLUMNS = ("x m", "x_dot m/s", "theta deg", "theta_dot deg/s")
PLANT_VS_CORE = "MuJoCo plant vs core `correct`, `semi_implicit`"
YARDSTICK = (f"yardstick: core `semi_implicit`, gravity {YARDSTICK_GRAVITY} vs "
             f"{GYM_PHYSICS['gravity']}")


def agent_params():
    """The preset's parameters with this experiment's trials and cap."""
    return params_from_strings(preset_values(PRESET)).replace(trials=TRIALS, max_steps=MAX_STEPS)


# ------------------------------------------------------------------------------------------------
# Learning
# ------------------------------------------------------------------------------------------------
def learn_on_mujoco(seed: int) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, float]:
    """One seed's episode, the pure core driving the MuJoCo plant (in a worker process)."""
    start = time.perf_counter()
    result = run_episode(seed, agent_params(), env_factory=MujocoCartPole)
    return (seed, result.steps, result.end_status, result.initial_angles,
            time.perf_counter() - start)


def mujoco_runs() -> tuple[dict, float, float]:
    """({seed: (steps, end status, angles)}, wall s, process s) over WORKERS processes."""
    runs, process_s = {}, 0.0
    start = time.perf_counter()
    # spawn: fresh workers (the parent later runs numba's threads; fork and threads do not mix)
    with multiprocessing.get_context("spawn").Pool(WORKERS) as pool:
        for seed, steps, status, angles, seconds in tqdm(
                pool.imap_unordered(learn_on_mujoco, SEEDS), total=len(SEEDS),
                desc="MuJoCo plant, pure core (seeds)", file=sys.stderr):
            runs[seed] = (steps, status, angles)
            process_s += seconds
    return runs, time.perf_counter() - start, process_s


def converged_count(steps: np.ndarray, max_steps: int) -> int:
    return int(np.sum(steps[:, -LAST:].mean(axis=1) >= CONVERGED * max_steps))


def summary_row(label: str, steps: np.ndarray, max_steps: int) -> list:
    """config | trials x cap | mean | median seed mean | last-64 mean | converged | stuck."""
    last = steps[:, -LAST:].mean(axis=1)
    converged = converged_count(steps, max_steps)
    return [label, f"{steps.shape[1]} x {max_steps:,}", f"{steps.mean():,.0f}",
            f"{np.median(steps.mean(axis=1)):,.0f}", f"{last.mean():,.0f}",
            f"{converged}/{len(steps)} ({converged / len(steps):.0%})",
            int(np.sum(last < STUCK * max_steps))]


def first_difference(a: np.ndarray, b: np.ndarray) -> int | None:
    """The first trial whose steps differ; None when all agree."""
    differ = np.flatnonzero(a != b)
    return int(differ[0]) if len(differ) else None


# ------------------------------------------------------------------------------------------------
# Plant against the core's physics
# ------------------------------------------------------------------------------------------------
def balancing_actions(steps: int) -> list[int]:
    plant = MujocoCartPole()
    plant.reset(at_rest(AGREEMENT_ANGLE_DEG))
    actions = []
    for _ in range(steps):
        _, _, theta_deg, theta_dot_deg = plant.state
        actions.append(int(theta_deg + LEAD_S * theta_dot_deg > 0))
        plant.step(actions[-1])
    return actions


def trajectory(env, actions: list[int]) -> np.ndarray:
    """(steps, 4): the state after each step of the sequence."""
    env.reset(at_rest(AGREEMENT_ANGLE_DEG))
    states = []
    for action in actions:
        env.step(action)
        states.append(env.state)
    return np.array(states)


def agreement() -> tuple[dict, float]:
    """({(comparison, k): max |difference| of each state variable over the first k steps},
    the largest |theta| deg of the plant under the sequence)."""
    actions = balancing_actions(max(AGREEMENT_STEPS))
    core = gym_matched_params(agent_params())
    semi_implicit = core.replace(integrator="semi_implicit")
    mujoco = trajectory(MujocoCartPole(), actions)
    pairs = [(PLANT_VS_CORE, mujoco,
              trajectory(CartPole(semi_implicit), actions)),
             ("MuJoCo plant vs core `correct`, `euler` (gymnasium's integrator)", mujoco,
              trajectory(CartPole(core), actions)),
             (YARDSTICK,
              trajectory(CartPole(semi_implicit.replace(gravity=YARDSTICK_GRAVITY)), actions),
              trajectory(CartPole(semi_implicit), actions))]
    worst = {(label, steps): np.abs(a[:steps] - b[:steps]).max(axis=0)
             for label, a, b in pairs for steps in AGREEMENT_STEPS}
    return worst, float(np.abs(mujoco[:, 2]).max())


def unstable_growth_per_second() -> float:
    """e^lambda: how much the upright pole's unstable mode grows in a second (the linearised
    equations of core/physics.py: lambda^2 = g / (l (4/3 - m / (M + m)))."""
    p = gym_matched_params(agent_params())
    total = p.cart_mass + p.pole_mass
    return math.exp(math.sqrt(p.gravity / (p.pole_length * (4 / 3 - p.pole_mass / total))))


def plant_microseconds_per_step(steps: int = 100_000) -> float:
    plant = MujocoCartPole()
    plant.reset(at_rest(0.0))
    start = time.perf_counter()
    for k in range(steps):
        plant.step(k & 1)  # alternating pushes keep it near upright
    return (time.perf_counter() - start) / steps * 1e6


# ------------------------------------------------------------------------------------------------
# Report
# ------------------------------------------------------------------------------------------------
def main() -> None:
    p = agent_params()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    load = os.getloadavg()[0]
    runs, wall_s, process_s = mujoco_runs()
    seeds = list(SEEDS)
    semi_implicit = gym_matched_params(p).replace(integrator="semi_implicit")
    euler = gym_matched_params(p)
    physics = {"semi_implicit": semi_implicit, "euler": euler}
    batch = {name: run_batch(seeds, q) for name, q in physics.items()}
    many = {name: run_batch(CONTEXT_SEEDS, q).steps for name, q in physics.items()}
    full = {name: run_batch(seeds, q.replace(trials=FULL_TRIALS, max_steps=FULL_MAX_STEPS)).steps
            for name, q in physics.items()}
    worst, theta_max = agreement()
    microseconds = plant_microseconds_per_step()
    growth = unstable_growth_per_second()

    configs = {"mujoco_core": [np.stack([runs[s][k] for s in seeds]) for k in range(3)],
               **{f"batch_{name}": [result.steps, result.end_status, result.initial_angles]
                  for name, result in batch.items()}}
    write_csv(CSV, ["config", "seed", "trial", "initial_angle_deg", "steps", "end_reason"],
              [(name, seed, t, angles[k, t], steps[k, t], END_REASONS[status[k, t]])
               for name, (steps, status, angles) in configs.items()
               for k, seed in enumerate(seeds) for t in range(TRIALS)])
    mujoco_steps = configs["mujoco_core"][0]

    firsts = [first_difference(mujoco_steps[k], batch["semi_implicit"].steps[k])
              for k in range(len(seeds))]
    identical = sum(f is None for f in firsts)
    differing = sorted(f for f in firsts if f is not None)
    parting = f"; in the others the first differing trial is {', '.join(map(str, differing))}" \
        if differing else ""
    total_steps = int(mujoco_steps.sum())
    table = md_table(
        ["config", "trials x cap", "mean steps", "median seed mean", f"last-{LAST} mean",
         f"converged (last-{LAST} mean >= {CONVERGED:.0%} of the cap)",
         f"stuck (last-{LAST} mean < {STUCK:.0%} of the cap)"],
        [summary_row("MuJoCo plant, pure core", mujoco_steps, MAX_STEPS),
         summary_row("core physics, gymnasium's constants, `semi_implicit` (batch engine)",
                     batch["semi_implicit"].steps, MAX_STEPS),
         summary_row("core physics, gymnasium's constants, `euler` = CartPole-v1 "
                     "(batch engine, `gym_matched_params`)", batch["euler"].steps, MAX_STEPS),
         *(summary_row(f"batch engine, `{name}`, seeds {CONTEXT_SEEDS[0]}-{CONTEXT_SEEDS[-1]}",
                       steps, MAX_STEPS) for name, steps in many.items()),
         *(summary_row(f"batch engine, `{name}`, the preset's own episode", steps,
                       FULL_MAX_STEPS) for name, steps in full.items())])
    blocks = [converged_count(many["semi_implicit"][k:k + len(seeds)], MAX_STEPS)
              for k in range(0, len(CONTEXT_SEEDS) - len(seeds) + 1, len(seeds))]
    agreement_table = md_table(
        ["comparison", "steps", *(f"max abs diff {c}" for c in STATE_COLUMNS)],
        [[label, steps, *(f"{v:.2e}" for v in values)] for (label, steps), values in worst.items()])
    values = ", ".join(f"{k}={v}" for k, v in preset_values(PRESET).items())
    DOC.write_text(f"""# The MuJoCo cart-pole

Generated by `python scripts/mujoco_learning.py` on {platform.node()} ({os.cpu_count()} cores,
Python {platform.python_version()}, load average {load:.1f} at the start, {started}); the
settings are at the top of the script. Data: `data/mujoco_learning.csv` (`config, seed, trial,
initial_angle_deg, steps, end_reason`; configs `mujoco_core`, `batch_semi_implicit`,
`batch_euler`).

## The plant

`clnn_ros/tasks/cartpole/mujoco_cartpole.py`, `MujocoCartPole`: an MJCF cart-pole stepped by MuJoCo, with
gymnasium CartPole-v1's constants: cart 1.0 kg on a frictionless slide joint, pole 0.1 kg on an
undamped hinge about y, centre of mass 0.5 m above the hinge and the inertia of a uniform 1.0 m
rod about its centre (0.1 x 1.0^2 / 12 kg m^2, so (4/3) m l^2 about the hinge, as in the
equations), gravity 9.8 m/s^2, contacts off, a motor on the slide (gear 1, +-10 N). One step is
one `mj_step` with timestep 0.02 s and MuJoCo's `Euler` integrator, which is semi-implicit Euler:
the discrete-time model the core, the batch engine and the paper step, with MuJoCo's rigid-body
algorithms in place of the closed-form equations. The failure limits (12 deg, then 2.4 m) are
checked after each step, as in the core. `clnn-run --env mujoco` runs it as the environment
node's simulator (`clnn_ros/nodes/environment.py`, `simulator:=mujoco`), and a node run equals
`run_episode(seed, p, env_factory=MujocoCartPole)` trial by trial (tests/test_mujoco_env.py).
MuJoCo alone takes {microseconds:.1f} us a step here (the agent, in pure Python, takes some
{1e6 * process_s / total_steps:.0f} us).

## Plant vs the core's physics

One action sequence of {max(AGREEMENT_STEPS)} steps (a balancing rule's, chosen on the plant: \
push toward
theta + {LEAD_S} s x theta_dot; the pole stays within {theta_max:.2f} deg) replayed open loop on \
each,
from the pole at rest at {AGREEMENT_ANGLE_DEG} deg; the largest difference of each state variable
within the first k steps:

{agreement_table}

The MuJoCo plant is the core's `correct` physics with `semi_implicit` integration to rounding:
the differences are last-bit differences (radians vs degrees, another order of operations)
amplified by the upright pole's instability: its unstable mode grows x{growth:.0f} a second, and
open loop nothing damps it, so after {max(AGREEMENT_STEPS)} steps \
({max(AGREEMENT_STEPS) * 0.02:g} s) even
rounding differences have grown into different motions (in closed loop as well, sooner or
later: see "Learning"). Gymnasium's explicit Euler is another discrete model, differing at first \
order in tau. A 0.1 %
error in one constant (gravity {YARDSTICK_GRAVITY}) moves the trajectory by far more than the plant
differs from the equations, so the agreement checks the model's masses, inertia, signs and
integrator. tests/test_mujoco_env.py bounds the difference over {TEST_STEPS} steps (a random
sequence) by 1e-9 in every variable: here the largest {TEST_STEPS}-step difference is
{worst[PLANT_VS_CORE, TEST_STEPS].max():.1e}, the yardstick's \
{worst[YARDSTICK, TEST_STEPS].max():.1e}.

## Learning

The unchanged agent with the `{PRESET}` preset's encoder and rule settings ({values}; its
physics values, gymnasium's with explicit Euler, do not change the MuJoCo plant, which has the
same constants and semi-implicit integration),
seeds {seeds[0]}-{seeds[-1]}, {TRIALS} trials, a cap of {MAX_STEPS:,} successful steps per trial \
(the
preset's own cap, 10,000, would take hours in the pure core); the MuJoCo runs used {WORKERS}
processes: {wall_s / 60:.1f} min wall, {total_steps:,} agent-steps,
{total_steps / process_s:,.0f} agent-steps/s a process. Each batch row runs the same seeds,
trials and cap on the core's own physics; as context, batch engine only, the same episode on
{len(CONTEXT_SEEDS)} seeds and the preset's own episode ({FULL_TRIALS} trials, cap \
{FULL_MAX_STEPS:,}).

{table}

The MuJoCo plant is the `semi_implicit` core physics to rounding (above), so its row and the
second differ by sampling alone: the {len(CONTEXT_SEEDS)} `semi_implicit` seeds, cut into blocks \
of {len(seeds)}, converge
in {min(blocks)} to {max(blocks)} of {len(seeds)} ({", ".join(map(str, blocks))}); the MuJoCo \
row: {converged_count(mujoco_steps, MAX_STEPS)}.

Trial by trial, the MuJoCo runs equal the batch engine's `semi_implicit` runs in all {TRIALS}
trials in {identical} of {len(seeds)} seeds{parting}. Where they part, a long balancing trial
amplified the plant's last-bit differences (table above) into another action, and from there
the episode goes its own way (the bang-bang controlled pole is chaotic), as the batch engine
and gymnasium part (docs/REPRODUCTION.md, "Gymnasium's physics"): the learning statistics are
what to compare.
""")
    print(f"wrote {DOC.relative_to(ROOT)} and {CSV.relative_to(ROOT)} ({wall_s / 60:.1f} min)")


if __name__ == "__main__":
    main()
