"""The task batch engine (clnn_ros.task_batch) and its compiled steps
(clnn_ros.tasks.classic_control) equal Gymnasium's own steps and the core's task episode, bit
for bit."""

from __future__ import annotations

import numpy as np
import pytest

from clnn_ros.core.episode import seed_setup
from clnn_ros.core.task_episode import run_task_episode
from clnn_ros.task_batch import compiles, run_compiled_task_episode
from clnn_ros.tasks import classic_control
from clnn_ros.tasks.gymnasium_task import make, task_params


@pytest.mark.parametrize("name", sorted(classic_control.COMPILED))
def test_a_compiled_step_is_gymnasiums_bit_for_bit(name):
    """Random actions from Gymnasium's own starts: every step's state, observation, reward and
    termination alike (the Acrobot's squares through libm's pow: as x * x, 11 of these 30
    trajectories part)."""
    import gymnasium

    code, env = classic_control.COMPILED[name], gymnasium.make(name)
    actions = np.random.default_rng(1)
    values, terminations = np.empty(env.observation_space.shape[0]), 0
    for trajectory in range(30):
        observation, _ = env.reset(seed=trajectory)
        state = classic_control.start_state(env)
        classic_control.observe(code, state, values)
        assert values.tolist() == observation.tolist()
        for _ in range(500):
            action = int(actions.integers(3))
            observation, reward, terminated, truncated, _ = env.step(action)
            assert classic_control.step(code, state, action) == (reward, terminated)
            classic_control.observe(code, state, values)
            assert values.tolist() == observation.tolist()
            assert state.tolist() == np.asarray(env.unwrapped.state, dtype=float).tolist()
            if terminated or truncated:
                terminations += terminated
                break
    assert name == "MountainCar-v0" or terminations > 0  # random swings reach Acrobot's line


@pytest.mark.parametrize("name, changes", [
    ("gymnasium:Acrobot-v1", {}),
    ("gymnasium:Acrobot-v1", {"tie_break": "random", "explore": "0.05", "tagging": "both_neurons",
                              "rerandomize_every": "3", "e_flag": "live"}),
    ("gymnasium:Acrobot-v1", {"reward_mapping": "failure", "inference": "exact",
                              "decay_counters": "carry", "success_counter": "carry",
                              "punish_timing": "after_decay", "tie_break": "index"}),
    ("gymnasium:MountainCar-v0", {}),
    ("gymnasium:MountainCar-v0", {"omega": "16", "variable_edges": "position:-0.5;velocity:0",
                                  "segments": "2"}),
])
def test_the_task_batch_engine_is_the_cores_episode_bit_for_bit(name, changes):
    task, _ = make(name)
    assert compiles(task)
    p = task_params(task, {"trials": "8", "sigma": "32", "omega": "64", **changes})
    ours = run_compiled_task_episode(7, p, task, make(name)[1])
    core = run_task_episode(7, p, task, make(name)[1])
    assert ours.steps.tolist() == core.steps.tolist()
    assert ours.returns.tolist() == core.returns.tolist()
    assert ours.terminated.tolist() == core.terminated.tolist()
    assert np.array_equal(ours.final_weights, core.final_weights)
    assert not np.array_equal(core.final_weights, seed_setup(7, p)[0])  # it learned
    frozen = run_compiled_task_episode(7, p, task, make(name)[1], learn=False)
    assert frozen.steps.tolist() == run_task_episode(7, p, task, make(name)[1],
                                                     learn=False).steps.tolist()


def test_only_the_compiled_steps_compile():
    assert not compiles(make("gymnasium:CartPole-v1")[0])
