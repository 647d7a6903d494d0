"""The field's control tasks as the field measures agents (issue 46): the RLN agent beside
stable-baselines3's PPO and DQN with rl-zoo3's tuned hyperparameters, task by task, written to
OUT/VERSUS_TASKS.md with a figure and a CSV per task.

    clnn-reproduce versus --task gymnasium:Acrobot-v1 [--seeds 0-127] [--deep-seeds 8]
                          [--agents rln,ppo,dqn] [--stored-only] [--out docs]

Gymnasium's own protocol for each task (its reset seeds, truncation and reward_threshold); an
agent solves at the first episode whose last 100 training returns average the threshold or
more, environment steps counted over all its environments (versus.seed_measures, as for
CartPole-v1). Each agent-seed is stored once finished (OUT/data/versus_tasks/ID/AGENT/) and not
run again: an interrupted run resumes, and the report covers every task stored so far.
"""

from __future__ import annotations

import importlib.util
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.params import Params
from ..core.presets import preset_values
from ..core.solving import WINDOW
from ..tasks.gymnasium_task import PREFIX, env_id, make, task_params
from .common import load_stored, md_table, progress, store_arrays, write_csv
from .task_learning import task_episode
from .versus import plot_returns, quartiles, seed_measures, stored_seed
from .workers import in_workers


@dataclass(frozen=True)
class TaskSetup:
    episodes: int  # the RLN agent's training episodes: at most rl-zoo3's PPO budget in steps
    preset: str | None = None  # the RLN agent's preset; None: the task's first encoding
    actions: str | None = None  # the RLN agent's declared values of a Box action space


TASKS = {
    "Acrobot-v1": TaskSetup(500, "acrobot_v1"),
    "MountainCar-v0": TaskSetup(1000, "mountain_car_v0"),
    "LunarLander-v3": TaskSetup(1000),
    "InvertedPendulum-v5": TaskSetup(1000, "inverted_pendulum_v5", actions="-1,1"),
    "InvertedDoublePendulum-v5": TaskSetup(1000, actions="-1,0,1"),
}
AGENTS = {"rln": "RLN agent", "ppo": "PPO, rl-zoo3's hyperparameters (stable-baselines3)",
          "dqn": "DQN, rl-zoo3's hyperparameters (stable-baselines3)"}
DEEP = ("ppo", "dqn")
PLAY_EPISODES = 100
PLAY_SEEDS = 1_000_000  # seed s plays from the starts of seed PLAY_SEEDS + s: not its training's


def task_id(task_name: str) -> str:
    """The Gymnasium ID of `gymnasium:ID`, one of TASKS; ValueError with one line otherwise."""
    identifier = env_id(task_name)
    if identifier not in TASKS:
        raise ValueError(f"versus --task takes {', '.join(PREFIX + t for t in TASKS)}; "
                         f"got {task_name}")
    return identifier


def rln_params(identifier: str) -> Params:
    setup = TASKS[identifier]
    task, _ = make(PREFIX + identifier, setup.actions)
    values = preset_values(setup.preset) if setup.preset else {}
    return task_params(task, {**values, "trials": str(setup.episodes)})


def rln_seed(identifier: str, seed: int) -> dict:
    """One seed of the RLN agent (in a worker process): its training and its frozen play in the
    task's own environment."""
    setup, p = TASKS[identifier], rln_params(identifier)
    task, env = make(PREFIX + identifier, setup.actions)
    task_episode(seed, p.replace(trials=1), task, make(PREFIX + identifier, setup.actions)[1])
    began = time.process_time()  # after the compiled code was loaded: it is not the learning's
    result = task_episode(seed, p, task, env)
    cpu_s = time.process_time() - began
    play = task_episode(PLAY_SEEDS + seed, p.replace(trials=PLAY_EPISODES), task,
                        make(PREFIX + identifier, setup.actions)[1], learn=False,
                        weights=result.final_weights)
    return dict(returns=result.returns, env_steps=np.cumsum(result.steps), cpu_s=cpu_s,
                play=play.returns)


def deep_seed(identifier: str, agent: str, seed: int) -> dict:
    """One seed of PPO or DQN (in a worker process), on the task's own action space."""
    import gymnasium

    from ..baselines.sb3_agents import train
    task, _ = make(PREFIX + identifier, TASKS[identifier].actions)
    run = train(agent, seed, env_id=identifier, threshold=task.reward_threshold)
    with gymnasium.make(identifier) as env:
        play = []
        for k in range(PLAY_EPISODES):
            observation, _ = env.reset(seed=2**32 + PLAY_SEEDS + seed if k == 0 else None)
            total, over = 0.0, False
            while not over:
                observation, reward, terminated, truncated, _ = env.step(run.action(observation))
                total, over = total + float(reward), terminated or truncated
            play.append(total)
    return dict(returns=run.returns, env_steps=run.env_steps, cpu_s=run.cpu_s,
                play=np.array(play))


def agent_key(identifier: str, agent: str) -> list | None:
    """What an agent-seed depends on (a change runs it anew); None for a deep agent without
    the baselines extra (versus.stored_seed then takes the latest stored)."""
    if agent == "rln":
        return [identifier, agent, rln_params(identifier).to_dict(), PLAY_EPISODES]
    if not all(importlib.util.find_spec(m) for m in ("rl_zoo3", "stable_baselines3")):
        return None
    import stable_baselines3

    from ..baselines.sb3_agents import zoo_entry
    entry = zoo_entry(agent, identifier)
    return [identifier, agent, entry and entry[0], stable_baselines3.__version__, PLAY_EPISODES]


def has_entry(identifier: str, agent: str) -> bool:
    """Whether the agent runs on the task: rl-zoo3 has DQN for discrete actions alone."""
    return agent != "dqn" or TASKS[identifier].actions is None


def run_task_versus(identifier: str, to_run: list[str], seeds: list[int], deep_seeds: int,
                    store: Path, workers: int) -> dict:
    """{agent: {seed: arrays}} of the task, every agent's stored seeds (so that a run of one
    agent leaves the others in the report), the agents in `to_run` run now where not stored.
    The deep agents on the first `deep_seeds` seeds."""
    results = {agent: {} for agent in AGENTS if has_entry(identifier, agent)}
    pending = {}
    for agent in results:
        key = agent_key(identifier, agent)
        for seed in seeds if agent == "rln" else seeds[:deep_seeds]:
            path = stored_seed(store / identifier / agent, seed, key)
            if path.exists():
                results[agent][seed] = load_stored(path)
            elif agent in to_run:
                pending[agent, seed] = path
    jobs = [(identifier, seed) if agent == "rln" else (identifier, agent, seed)
            for agent, seed in pending]
    if jobs:
        finished = in_workers(_one, jobs, workers)
        for job, arrays in progress(finished, f"versus {identifier}: {len(jobs)} agent-seeds"):
            agent, seed = ("rln", job[1]) if len(job) == 2 else job[1:]
            results[agent][seed] = arrays
            store_arrays(pending[agent, seed], arrays)
    return results


def _one(*job) -> dict:
    """A job of run_task_versus: (ID, seed) of the RLN agent or (ID, agent, seed) of a deep one."""
    return rln_seed(*job) if len(job) == 2 else deep_seed(*job)


def task_section(identifier: str, results: dict, out: Path) -> tuple[list[str], list[list]]:
    """The task's section of the report (its table, figure, and what the RLN agent ran), its
    figure and CSV written; and its rows of the summary table."""
    task, _ = make(PREFIX + identifier, TASKS[identifier].actions)
    threshold = task.reward_threshold
    labels = {**AGENTS, "rln": rln_label(identifier)}
    rows, summary, against = [], [], []
    for agent, seeds in results.items():
        if not seeds:
            continue
        measures = [seed_measures(arrays, threshold) for arrays in seeds.values()]
        solved = [m for m in measures if m["solved"] is not None]
        played = np.array([m["play"] for m in measures])
        cpu = sum(m["cpu_s"] for m in measures)
        steps = quartiles([m["steps"] for m in solved])
        per_solved = f"{cpu / len(solved):.3g}" if solved else "—"
        if agent != "rln" and solved:
            against.append(comparison(labels[agent], seeds, results.get("rln", {}), threshold))
        rows.append([labels[agent], f"{len(solved)} of {len(measures)}",
                     quartiles([m["solved"] for m in solved]), steps, per_solved,
                     f"{played.mean():.1f}; {np.mean(played >= threshold):.0%}"])
        summary.append([identifier, labels[agent], f"{len(solved)} of {len(measures)}",
                        steps.split(" ")[0], per_solved, f"{np.mean(played >= threshold):.0%}"])
    figure = plot_returns({a: s for a, s in results.items() if s},
                          out / "figures" / f"versus_{identifier}.png", identifier, threshold,
                          labels)
    write_csv(out / "data" / f"versus_{identifier}_seeds.csv",
              ["agent", "seed", "solved_episode", "steps_to_solve", "episodes", "env_steps",
               "cpu_s", "frozen_play_mean"],
              ([agent, seed, *[("" if v is None else v) for v in
                               seed_measures(arrays, threshold).values()]]
               for agent, seeds in results.items() for seed, arrays in sorted(seeds.items())))
    text = [f"## {identifier}", "",
            f"Threshold {threshold:g}; truncated at {task.max_steps} steps; "
            f"{len(task.actions)} actions for the RLN agent "
            f"({', '.join(task.action_labels)}). The RLN agent: {rln_label(identifier)}, "
            f"{TASKS[identifier].episodes} training episodes.", "",
            md_table(["agent", "seeds solved", "episodes to solve: median (quartiles)",
                      "environment steps to solve: median (quartiles)", "CPU s per solved seed",
                      f"frozen play: mean return; seeds >= {threshold:g}"], rows), "",
            *[line for line in against if line],
            "",
            f"![{identifier}: return against environment steps]({figure.relative_to(out)})",
            f"Per seed: [data/versus_{identifier}_seeds.csv](data/versus_{identifier}_seeds.csv)",
            ""]
    return text, summary


def comparison(label: str, seeds: dict, rln: dict, threshold: float) -> str:
    """The RLN agent against another, on the other's seeds: how many times fewer environment
    steps to solve (medians) and how many times less CPU per solved seed; "" where the RLN
    agent solved none of them."""
    def solving(arrays_by_seed: dict) -> tuple[float, float] | None:
        measures = [seed_measures(a, threshold) for a in arrays_by_seed.values()]
        solved = [m for m in measures if m["solved"] is not None]
        if not solved:
            return None
        return (float(np.median([m["steps"] for m in solved])),
                sum(m["cpu_s"] for m in measures) / len(solved))
    other, mine = solving(seeds), solving({s: a for s, a in rln.items() if s in seeds})
    if other is None or mine is None:
        return ""
    return (f"* RLN agent against {label}, on its {len(seeds)} seeds: "
            f"{other[0] / mine[0]:.2f}x fewer environment steps to solve (medians); "
            f"{other[1] / mine[1]:,.0f}x less CPU time per solved seed.")


def rln_label(identifier: str) -> str:
    preset = TASKS[identifier].preset
    return f"RLN agent, preset {preset}" if preset else \
        "RLN agent, the task's first encoding (no preset chosen)"


def write_task_versus(results_by_task: dict, out: Path) -> Path:
    """OUT/VERSUS_TASKS.md: a section per task stored, and one summary table."""
    sections, summary = [], []
    for identifier, results in results_by_task.items():
        text, rows = task_section(identifier, results, out)
        sections += text
        summary += rows
    text = [
        "# The field's control tasks as the field measures them", "",
        "Made by `clnn-reproduce versus --task gymnasium:ID` for each task (stored agent-seeds "
        "are not run again; `--stored-only` rewrites this page from them). Each task's own "
        f"protocol (Gymnasium's reset seeds, truncation and threshold); solved at the first "
        f"episode whose last {WINDOW} training returns average the threshold or more; "
        "environment steps counted over all of an agent's environments; PPO and DQN with "
        "rl-zoo3's hyperparameters for the task (for the MuJoCo tasks its InvertedPendulum-v2 "
        "and InvertedDoublePendulum-v2 entries, on the task's own continuous actions; DQN "
        "where rl-zoo3 has it), stopped once solved, else at rl-zoo3's budget. *Frozen play*: "
        f"the final policy without learning, {PLAY_EPISODES} episodes from starts no training "
        "saw (the same for every agent); mean return and the share of seeds averaging the "
        "threshold. *CPU s per solved seed*: the CPU time of all the agent's seeds over the "
        "seeds that solved. How each preset was chosen: [TASKS.md](TASKS.md).", "",
        md_table(["task", "agent", "seeds solved", "median environment steps to solve",
                  "CPU s per solved seed", "frozen play: seeds >= threshold"], summary), "",
        *sections]
    out.mkdir(parents=True, exist_ok=True)
    path = out / "VERSUS_TASKS.md"
    path.write_text("\n".join(text) + "\n")
    return path


def check_agents(agents: list[str], stored_only: bool) -> None:
    """ValueError with one line for an unknown agent, or a deep one to run without its extra."""
    for agent in agents:
        if agent not in AGENTS:
            raise ValueError(f"unknown agent {agent!r} for --task; known: {', '.join(AGENTS)}")
    if set(agents) & set(DEEP) and not stored_only and not all(
            importlib.util.find_spec(m) for m in ("rl_zoo3", "stable_baselines3")):
        raise ValueError(f"{', '.join(DEEP)} need the baselines extra: pip install -e "
                         "'.[baselines]' (docs/VERSUS_TASKS.md)")
