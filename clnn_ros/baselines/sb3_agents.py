"""stable-baselines3's PPO and DQN on CartPole-v1 with rl-zoo3's tuned hyperparameters, read from
the rl_zoo3 package's own hyperparameter files, judged as every agent here is (core.solving):
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

from ..core.solving import solved_episode

ENV_ID = "CartPole-v1"
ALGORITHMS = ("ppo", "dqn")


@dataclass
class TrainingRun:
    returns: np.ndarray  # each training episode's return, in the order they ended
    env_steps: np.ndarray  # the agent's environment steps when each ended
    cpu_s: float  # the process's CPU time for the training (every thread)
    action: Callable[[object], int]  # the trained policy, deterministic: observation -> action


def zoo_entry(algorithm: str) -> tuple[dict, Path]:
    """rl-zoo3's CartPole-v1 entry for the algorithm, as its file has it, and the file."""
    import rl_zoo3

    path = Path(rl_zoo3.__file__).parent / "hyperparams" / f"{algorithm}.yml"
    return dict(yaml.safe_load(path.read_text())[ENV_ID]), path


def model_arguments(entry: dict, budget_factor: int = 1) -> tuple[dict, int, int]:
    """(the model's keyword arguments, n_envs, n_timesteps) of a zoo entry, its schedules
    ("lin_X": linearly from X to 0 over the training) and policy_kwargs (a Python expression
    of dicts and lists) turned into objects as rl-zoo3's ExperimentManager does. A
    `budget_factor` multiplies n_timesteps and keeps DQN's exploration schedule in steps (its
    exploration_fraction is of the whole training), so that the agent only trains longer."""
    from rl_zoo3.utils import linear_schedule

    arguments = dict(entry)
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


def train(algorithm: str, seed: int, budget_factor: int = 1) -> TrainingRun:
    """One seed of the algorithm, for rl-zoo3's budget (times `budget_factor`) or until it has
    solved CartPole-v1 (the point of solving is the same either way: it is judged on the
    training returns). One torch thread: the seeds of a benchmark run side by side, one a
    core."""
    import torch
    from stable_baselines3 import DQN, PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import Logger

    torch.set_num_threads(1)
    arguments, n_envs, n_timesteps = model_arguments(zoo_entry(algorithm)[0], budget_factor)
    returns, env_steps = [], []

    class EpisodeRecorder(BaseCallback):
        def _on_step(self) -> bool:
            for info in self.locals["infos"]:
                if "episode" in info:  # the Monitor of make_vec_env: an episode ended
                    returns.append(int(info["episode"]["r"]))
                    env_steps.append(self.num_timesteps)
            return solved_episode(returns) is None

    env = make_vec_env(ENV_ID, n_envs=n_envs, seed=seed)
    model = {"ppo": PPO, "dqn": DQN}[algorithm](env=env, seed=seed, device="cpu", verbose=0,
                                                **arguments)
    # A logger of no output: the default one makes an empty /tmp/SB3-<time> folder each run.
    model.set_logger(Logger(folder=None, output_formats=[]))
    began = time.process_time()
    model.learn(total_timesteps=n_timesteps, callback=EpisodeRecorder())
    cpu_s = time.process_time() - began
    env.close()
    return TrainingRun(np.array(returns), np.array(env_steps), cpu_s,
                       lambda observation: int(model.predict(observation, deterministic=True)[0]))
