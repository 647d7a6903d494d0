"""CartPole-v1 as the RL field measures agents (issue 34): the RLN agent (preset cartpole_v1)
beside the field's agents in one run: the same protocol, the same seeds, the same machine.
Written to OUT/VERSUS.md with a figure and a CSV.

    clnn-reproduce versus [--seeds 0-127] [--agents rln,rln_mujoco,ase_ace,ppo,dqn,dqn_4x]
                          [--out docs]

Every agent is judged alike (core.solving): on the returns of its training episodes, solved at
the first episode whose last 100 average 475 or more; environment steps counted over all its
environments. Each agent-seed is stored once finished (OUT/data/versus/) and not run again:
an interrupted run resumes. ppo, dqn and dqn_4x need the baselines extra (pip install -e
'.[baselines]'); the others run from the README's setup.
"""

from __future__ import annotations

import importlib.util
import time
from pathlib import Path

import gymnasium
import numpy as np

from ..batch import run_batch
from ..core.episode import returns as episode_returns, run_episode
from ..core.params import Params, params_from_strings
from ..core.presets import preset_values
from ..core.solving import SOLVED_MEAN, WINDOW, solved_episode
from .common import load_stored, md_table, progress, store_arrays, store_path, write_csv
from .gym_eval import GYM_ID, FrozenPolicy, frozen, play, reset_seed
from .workers import in_workers

AGENTS = {
    "rln": "RLN agent, preset cartpole_v1 (the batch engine)",
    "rln_mujoco": "RLN agent, preset cartpole_v1, on the MuJoCo cart-pole (the pure core)",
    "ase_ace": "ASE/ACE on the 162 boxes (Barto, Sutton & Anderson 1983)",
    "ppo": "PPO, rl-zoo3's hyperparameters (stable-baselines3)",
    "dqn": "DQN, rl-zoo3's hyperparameters (stable-baselines3)",
    "dqn_4x": "DQN, rl-zoo3's hyperparameters, 4x its budget (stable-baselines3)",
}
# The baselines extra's agents: (stable-baselines3 algorithm, factor on rl-zoo3's budget).
# dqn_4x: DQN given room to solve (rl-zoo3's 50,000 steps leave it none, CARTPOLE_V1.md).
DEEP = {"ppo": ("ppo", 1), "dqn": ("dqn", 1), "dqn_4x": ("dqn", 4)}
PRESET = "cartpole_v1"
EPISODES = 512  # the budget of the RLN agents and ASE/ACE (PPO and DQN: rl-zoo3's n_timesteps)
PLAY_EPISODES = 100  # frozen play in gymnasium.make("CartPole-v1"), starts as gym-eval's
# Agents run on the first this many seeds alone: MuJoCo (5 s a seed), DQN 4x (5 CPU-min).
FIRST_SEEDS = {"rln_mujoco": 32, "dqn_4x": 16}


def rln_params() -> Params:
    return params_from_strings({**preset_values(PRESET), "trials": str(EPISODES)})


def has_baselines_extra() -> bool:
    return all(importlib.util.find_spec(name) is not None
               for name in ("rl_zoo3", "stable_baselines3"))


def check_agents(names: list[str], stored_only: bool = False) -> None:
    """ValueError with one line for an unknown agent, or a deep-RL one to run without its extra
    (the report of stored seeds, `stored_only`, runs none)."""
    for name in names:
        if name not in AGENTS:
            raise ValueError(f"unknown agent {name!r}; known: {', '.join(AGENTS)}")
    if set(names) & set(DEEP) and not stored_only and not has_baselines_extra():
        raise ValueError(f"{', '.join(DEEP)} need the baselines extra: pip install -e "
                         "'.[baselines]' (docs/VERSUS.md)")


def frozen_play(action, seed: int) -> np.ndarray:
    """PLAY_EPISODES episodes of a seed's frozen policy (observation -> action) in CartPole-v1
    itself, from the starts gym-eval gives the seed: every agent's seed s plays the same."""
    class Policy:
        def action(self, observation):
            return action(observation)
    with gymnasium.make(GYM_ID) as env:
        return np.array([play(Policy(), env, reset_seed(seed, k, 0))
                         for k in range(PLAY_EPISODES)])


def one_seed(agent: str, seed: int) -> dict:
    """One seed of an agent other than `rln` (in a worker process): its training returns, the
    environment steps when each ended, its CPU seconds and its frozen play (none on MuJoCo)."""
    if agent == "rln_mujoco":
        from ..tasks.cartpole.mujoco_cartpole import MujocoCartPole
        began = time.process_time()
        result = run_episode(seed, rln_params(), env_factory=MujocoCartPole)
        cpu_s = time.process_time() - began
        returns = episode_returns(result.steps, result.end_status)
        return dict(returns=returns, env_steps=np.cumsum(returns), cpu_s=cpu_s,
                    play=np.zeros(0, dtype=np.int64))
    if agent == "ase_ace":
        from ..baselines.ase_ace import new_agent, train
        learner = new_agent(seed)
        began = time.process_time()
        returns = train(seed, EPISODES, agent=learner)
        cpu_s = time.process_time() - began
        return dict(returns=returns, env_steps=np.cumsum(returns), cpu_s=cpu_s,
                    play=frozen_play(learner.frozen_action, seed))
    from ..baselines.sb3_agents import train as train_deep
    algorithm, budget_factor = DEEP[agent]
    run = train_deep(algorithm, seed, budget_factor)
    return dict(returns=run.returns, env_steps=run.env_steps, cpu_s=run.cpu_s,
                play=frozen_play(lambda observation: int(run.action(observation)), seed))


def agent_key(agent: str) -> list | None:
    """What an agent's stored seeds depend on (a change runs them anew); None for a deep-RL
    agent without the baselines extra (its versions unknown here: stored_seed)."""
    if agent in ("rln", "rln_mujoco"):
        return [agent, rln_params().to_dict(), PLAY_EPISODES]
    if agent in DEEP and not has_baselines_extra():
        return None
    if agent in DEEP:
        from ..baselines.sb3_agents import zoo_entry
        import stable_baselines3
        return [agent, zoo_entry(DEEP[agent][0])[0], stable_baselines3.__version__,
                PLAY_EPISODES]
    return [agent, EPISODES, PLAY_EPISODES]


def agent_seeds(agent: str, seeds: list[int]) -> list[int]:
    return seeds[:FIRST_SEEDS[agent]] if agent in FIRST_SEEDS else seeds


def stored_seed(folder: Path, seed: int, key: list | None) -> Path:
    """Where an agent-seed is stored; with no key (a deep-RL agent's report without its extra),
    the seed's latest stored file, whatever versions made it (docs/VERSUS.md names them)."""
    if key is not None:
        return store_path(folder, f"seed_{seed}", [key, seed])
    found = sorted(folder.glob(f"seed_{seed}_*.npz"), key=lambda path: path.stat().st_mtime)
    return found[-1] if found else folder / f"seed_{seed}_none.npz"


def run_versus(agents: list[str], seeds: list[int], store: Path, workers: int,
               stored_only: bool = False) -> dict:
    """{agent: {seed: arrays}}: each agent-seed stored, or run now and stored (stored_only:
    left out)."""
    results = {agent: {} for agent in agents}
    pending = []
    for agent in agents:
        key = agent_key(agent)
        for seed in agent_seeds(agent, seeds):
            path = stored_seed(store / agent, seed, key)
            if path.exists():
                results[agent][seed] = load_stored(path)
            elif not stored_only:
                pending.append((agent, seed, path))
    rln_pending = [(seed, path) for agent, seed, path in pending if agent == "rln"]
    if rln_pending:  # all at once in the batch engine, its CPU time shared out evenly
        p = rln_params()
        run_batch([0], p.replace(trials=1))  # the engine loaded (compiled) before it is timed
        began = time.process_time()
        batch = run_batch([seed for seed, _ in rln_pending], p)
        cpu_s = (time.process_time() - began) / len(rln_pending)
        for k, (seed, path) in enumerate(progress(rln_pending, "rln frozen play")):
            policy = FrozenPolicy(frozen(p), batch.final_weights[k], seed)
            returns = episode_returns(batch.steps[k], batch.end_status[k])
            results["rln"][seed] = dict(returns=returns, env_steps=np.cumsum(returns),
                                        cpu_s=np.float64(cpu_s),
                                        play=frozen_play(policy.action, seed))
            store_arrays(path, results["rln"][seed])
    others = {(agent, seed): path for agent, seed, path in pending if agent != "rln"}
    if others:
        finished = in_workers(one_seed, others, workers)
        for (agent, seed), result in progress(finished, f"versus: {len(others)} agent-seeds"):
            results[agent][seed] = result
            store_arrays(others[agent, seed], result)
    return results


def seed_measures(arrays: dict, threshold: float = SOLVED_MEAN) -> dict:
    """One agent-seed's measures: the episode it solved at (None) and the environment steps by
    then, its episodes and steps in all, CPU seconds, frozen play's mean return."""
    returns, env_steps = arrays["returns"], arrays["env_steps"]
    solved = solved_episode(returns, threshold)
    return dict(solved=solved, steps=None if solved is None else int(env_steps[solved - 1]),
                episodes=len(returns), env_steps=int(env_steps[-1]) if len(env_steps) else 0,
                cpu_s=float(arrays["cpu_s"]),
                play=float(np.mean(arrays["play"])) if len(arrays["play"]) else None)


def quartiles(values) -> str:
    if not values:
        return "—"
    q1, q2, q3 = np.percentile(values, (25, 50, 75))
    return f"{q2:,.0f} ({q1:,.0f}-{q3:,.0f})"


def agent_row(agent: str, seeds: dict) -> tuple[list, dict]:
    measures = [seed_measures(arrays) for arrays in seeds.values()]
    solved = [m for m in measures if m["solved"] is not None]
    played = [m["play"] for m in measures if m["play"] is not None]
    cpu = sum(m["cpu_s"] for m in measures)
    summary = dict(seeds=len(measures), solved=len(solved),
                   median_steps=float(np.median([m["steps"] for m in solved])) if solved else None,
                   cpu_per_solved=cpu / len(solved) if solved else None)
    row = [AGENTS[agent], f"{len(solved)} of {len(measures)}",
           quartiles([m["solved"] for m in solved]), quartiles([m["steps"] for m in solved]),
           f"{summary['cpu_per_solved']:.3g}" if solved else "—",
           f"{np.mean(played):.1f}; {np.mean(np.array(played) >= SOLVED_MEAN):.0%}"
           if played else "—"]
    return row, summary


def plot_returns(results: dict, path: Path, title: str = "CartPole-v1",
                 threshold: float = SOLVED_MEAN, labels: dict = AGENTS) -> Path:
    """Return against environment steps: per agent, the median and quartiles over seeds of the
    mean of each seed's last 10 returns at each step (a seed that stopped, solved, keeps its
    last value); the task's threshold."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ends = [a["env_steps"] for seeds in results.values() for a in seeds.values()
            if len(a["env_steps"])]
    # from the step where every seed has ended an episode: no point without a return
    grid = np.linspace(max(int(e[0]) for e in ends), max(int(e[-1]) for e in ends), 400)
    fig, ax = plt.subplots(figsize=(8, 4.5), constrained_layout=True)
    for agent, seeds in results.items():
        curves = []
        for a in seeds.values():
            smooth = np.convolve(a["returns"], np.ones(10) / 10)[:len(a["returns"])]
            index = np.searchsorted(a["env_steps"], grid, side="right") - 1
            curves.append(np.where(index >= 0, smooth[np.maximum(index, 0)], np.nan))
        if not curves:
            continue
        q1, q2, q3 = np.nanpercentile(np.array(curves), (25, 50, 75), axis=0)
        line, = ax.plot(grid, q2, label=labels[agent])
        ax.fill_between(grid, q1, q3, color=line.get_color(), alpha=0.2)
    ax.axhline(threshold, color="grey", linestyle=":", linewidth=1)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("return (mean of the last 10 episodes)")
    ax.set_title(f"{title}: median and quartiles over seeds")
    ax.legend(fontsize=7)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_versus(results: dict, run_seeds: list[int], seeds_spec: str, out: Path,
                 elapsed_s: float) -> Path:
    """OUT/VERSUS.md, OUT/figures/versus_returns.png, OUT/data/versus_seeds.csv."""
    rows, summaries = [], {}
    for agent, seeds in results.items():
        row, summaries[agent] = agent_row(agent, seeds)
        rows.append(row)
    write_csv(out / "data" / "versus_seeds.csv",
              ["agent", "seed", "solved_episode", "steps_to_solve", "episodes", "env_steps",
               "cpu_s", "frozen_play_mean"],
              ([agent, seed, *[("" if v is None else v) for v in seed_measures(a).values()]]
               for agent, seeds in results.items() for seed, a in sorted(seeds.items())))
    figure = plot_returns(results, out / "figures" / "versus_returns.png")
    text = [
        "# CartPole-v1 as the RL field measures it", "",
        f"Made by `clnn-reproduce versus --seeds {seeds_spec}` ({elapsed_s / 60:.0f} min of "
        "this run; stored agent-seeds are not run again). Every agent on the same machine, "
        "the same seeds, CartPole-v1's own protocol (random starts, truncation at 500), and "
        f"judged alike: on its training returns, solved at the first episode whose last "
        f"{WINDOW} average {SOLVED_MEAN} or more, environment steps counted over all its "
        "environments. *Frozen play*: the final policy without learning or exploration, "
        f"{PLAY_EPISODES} episodes in `gymnasium.make(\"CartPole-v1\")` (the same starts for "
        f"every agent): mean return; share of seeds averaging {SOLVED_MEAN}. The protocol, "
        "the preset `cartpole_v1` and how it was chosen: [CARTPOLE_V1.md](CARTPOLE_V1.md).", "",
        f"*Training length*: the RLN agents run all {EPISODES} episodes (the batch engine runs "
        "whole episodes); ASE/ACE, PPO and DQN stop once solved (where they solve is the same "
        f"either way), else at their budget: ASE/ACE {EPISODES} episodes, PPO and DQN "
        "rl-zoo3's `n_timesteps`, DQN 4x four times that with rl-zoo3's exploration schedule "
        "kept in steps (epsilon from 1 to 0.04 over the first 8,000; not rl-zoo3's tuned "
        f"agent: DQN given room to solve, on the first {FIRST_SEEDS['dqn_4x']} seeds; the "
        f"MuJoCo agent on the first {FIRST_SEEDS['rln_mujoco']}). Frozen play is of the final "
        "policy: the RLN agent's after "
        f"{EPISODES} episodes, the others' where they stopped. *CPU s per solved seed*: the CPU "
        "time of all the agent's seeds (every thread; for the batch engine its run shared out "
        "evenly) over the seeds that solved.", "",
        md_table(["agent", "seeds solved", "episodes to solve: median (quartiles)",
                  "environment steps to solve: median (quartiles)", "CPU s per solved seed",
                  "frozen play: mean return; seeds >= 475"], rows), "",
        f"![return against environment steps]({figure.relative_to(out)})", "",
    ]
    partial = [f"{AGENTS[agent]}: {len(done)} of its {len(agent_seeds(agent, run_seeds))} seeds"
               for agent, done in results.items()
               if len(done) < len(agent_seeds(agent, run_seeds))]
    if partial:
        text += [f"Partial (`--stored-only`, the rest not run yet): {'; '.join(partial)}. Its "
                 "row and figures are of those seeds alone.", ""]
    missing = [agent for agent in AGENTS if agent not in results]
    if missing:
        text += [f"Not in this run: {', '.join(AGENTS[a] for a in missing)} (`--agents`; "
                 f"{', '.join(DEEP)} need the baselines extra, pip install -e '.[baselines]').",
                 ""]
    for agent in DEEP:
        other = summaries.get(agent)
        if not (other and other["median_steps"]):
            continue
        # the RLN agent on the other's seeds (an agent of FIRST_SEEDS runs on fewer)
        rln = agent_row("rln", {seed: arrays for seed, arrays in results.get("rln", {}).items()
                                if seed in results[agent]})[1]
        if rln["median_steps"]:
            text.append(f"* RLN agent against {AGENTS[agent]}, on its {other['seeds']} seeds: "
                        f"{other['median_steps'] / rln['median_steps']:.2f}x fewer environment "
                        f"steps to solve (medians); "
                        f"{other['cpu_per_solved'] / rln['cpu_per_solved']:,.0f}x less CPU time "
                        f"per solved seed.")
    out.mkdir(parents=True, exist_ok=True)
    path = out / "VERSUS.md"
    path.write_text("\n".join(text) + "\n")
    return path
