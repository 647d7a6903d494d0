"""A Gymnasium task whose observation turns to NaN at its third step (a broken simulator), for
the environment node's refusal: `gymnasium:nan_task:NanObservation-v0` with tests/ on the path
(Gymnasium imports the module before the ID)."""

import gymnasium as gym
import numpy as np
from gymnasium import spaces


class NanObservation(gym.Env):
    observation_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)
    action_space = spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.steps = 0
        return np.zeros(2), {}

    def step(self, action):
        self.steps += 1
        value = np.nan if self.steps == 3 else 0.5
        return np.full(2, value), 1.0, False, False, {}


gym.register("NanObservation-v0", entry_point=NanObservation, max_episode_steps=50)
