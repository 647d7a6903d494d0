"""stable-baselines3's PPO and DQN on CartPole-v1 (or another Gymnasium task) with rl-zoo3's tuned
hyperparameters, read from the rl_zoo3 package's own hyperparameter files, judged as every agent
here is (core.solving):
the returns of their training episodes, in the order the episodes end over all the agent's
environments, and the environment steps the agent had taken (over all its environments) when
each ended.

Needs the `baselines` extra (`pip install -e '.[baselines]'`: stable-baselines3, rl_zoo3 and a
CPU build of torch); nothing else of the project imports this module.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from ..core.solving import SOLVED_MEAN, solved_episode

ENV_ID = "CartPole-v1"
ALGORITHMS = ("ppo", "dqn")
# Tasks whose rl-zoo3 entry is under another version's name: its MuJoCo entries are v2's
ZOO_NAMES = {"InvertedPendulum-v5": "InvertedPendulum-v2",
             "InvertedDoublePendulum-v5": "InvertedDoublePendulum-v2"}


@dataclass
class TrainingRun:
    returns: np.ndarray  # each training episode's return, in the order they ended
    env_steps: np.ndarray  # the agent's environment steps when each ended
    cpu_s: float  # the process's CPU time for the training (every thread)
    action: Callable[[object], int]  # the trained policy, deterministic: observation -> action


def zoo_entry(algorithm: str, env_id: str = ENV_ID) -> tuple[dict, Path] | None:
    """rl-zoo3's entry of the task for the algorithm, as its file has it, and the file; None
    where rl-zoo3 has none (e.g. DQN for a continuous action space)."""
    import rl_zoo3

    path = Path(rl_zoo3.__file__).parent / "hyperparams" / f"{algorithm}.yml"
    entry = yaml.safe_load(path.read_text()).get(ZOO_NAMES.get(env_id, env_id))
    return None if entry is None else (dict(entry), path)


def model_arguments(entry: dict, budget_factor: int = 1) -> tuple[dict, int, int]:
    """(the model's keyword arguments, n_envs, n_timesteps) of a zoo entry (its `normalize`
    left out: train() wraps the environments for it), its schedules
    ("lin_X": linearly from X to 0 over the training) and policy_kwargs (a Python expression
    of dicts and lists) turned into objects as rl-zoo3's ExperimentManager does. A
    `budget_factor` multiplies n_timesteps and keeps DQN's exploration schedule in steps (its
    exploration_fraction is of the whole training), so that the agent only trains longer."""
    from rl_zoo3.utils import linear_schedule

    arguments = {k: v for k, v in entry.items() if k != "normalize"}
    n_envs = int(arguments.pop("n_envs", 1))
    n_timesteps = int(arguments.pop("n_timesteps")) * budget_factor
    if budget_factor != 1:
        if any(isinstance(v, str) and v.startswith("lin_") for v in arguments.values()):
            raise ValueError("a longer budget would stretch this entry's lin_ schedules")
        if "exploration_fraction" in arguments:
            arguments["exploration_fraction"] /= budget_factor
    for name, value in arguments.items():
        if isinstance(value, str) and value.startswith("lin_"):
            arguments[name] = linear_schedule(float(value.removeprefix("lin_")))
    if isinstance(arguments.get("policy_kwargs"), str):
        arguments["policy_kwargs"] = eval(arguments["policy_kwargs"],  # the zoo's own file
                                          {"__builtins__": {}, "dict": dict})
    return arguments, n_envs, n_timesteps


def train(algorithm: str, seed: int, budget_factor: int = 1, env_id: str = ENV_ID,
          threshold: float = SOLVED_MEAN) -> TrainingRun:
    """One seed of the algorithm on the task, for rl-zoo3's budget (times `budget_factor`) or
    until it has solved the task (its last 100 training returns averaging `threshold`; the
    point of solving is the same either way: it is judged on the training returns). An entry
    with `normalize` trains on normalized observations and rewards (VecNormalize, as rl-zoo3's
    ExperimentManager does; the returns recorded are the task's own) and plays on observations
    normalized by its statistics. One torch thread: the seeds of a benchmark run side by side,
    one a core."""
    import torch
    from stable_baselines3 import DQN, PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import VecNormalize

    torch.set_num_threads(1)
    entry = zoo_entry(algorithm, env_id)
    if entry is None:
        raise ValueError(f"rl-zoo3 has no {algorithm} entry for {env_id}")
    arguments, n_envs, n_timesteps = model_arguments(entry[0], budget_factor)
    returns, env_steps = [], []

    class EpisodeRecorder(BaseCallback):
        def _on_step(self) -> bool:
            for info in self.locals["infos"]:
                if "episode" in info:  # the Monitor of make_vec_env: an episode ended
                    returns.append(float(info["episode"]["r"]))
                    env_steps.append(self.num_timesteps)
            return solved_episode(returns, threshold) is None

    env = make_vec_env(env_id, n_envs=n_envs, seed=seed)
    if entry[0].get("normalize"):
        env = VecNormalize(env, gamma=arguments.get("gamma", 0.99))
    model = {"ppo": PPO, "dqn": DQN}[algorithm](env=env, seed=seed, device="cpu", verbose=0,
                                                **arguments)
    # A logger of no output: the default one makes an empty /tmp/SB3-<time> folder each run.
    model.set_logger(Logger(folder=None, output_formats=[]))
    began = time.process_time()
    model.learn(total_timesteps=n_timesteps, callback=EpisodeRecorder())
    cpu_s = time.process_time() - began
    env.close()
    seen = env.normalize_obs if isinstance(env, VecNormalize) else (lambda observation: observation)
    return TrainingRun(np.array(returns), np.array(env_steps), cpu_s,
                       lambda observation: model.predict(seen(observation), deterministic=True)[0])
