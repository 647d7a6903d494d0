"""The field's deep-RL agents (clnn_ros.baselines.sb3_agents) take rl-zoo3's own CartPole-v1
hyperparameters as rl-zoo3 does. Needs the baselines extra: skipped without it (the README's
two commands do not install it)."""

import pytest

pytest.importorskip("rl_zoo3")
pytest.importorskip("stable_baselines3")

from clnn_ros.baselines.sb3_agents import model_arguments, zoo_entry  # noqa: E402


def test_ppo_takes_the_zoos_entry_with_its_schedules():
    arguments, n_envs, n_timesteps = model_arguments(zoo_entry("ppo")[0])
    assert (n_envs, n_timesteps) == (8, 100_000)
    assert arguments["n_steps"] == 32 and arguments["policy"] == "MlpPolicy"
    assert arguments["learning_rate"](1.0) == pytest.approx(0.001)  # lin_0.001 at the start
    assert arguments["learning_rate"](0.0) == 0.0  # ... and at the end


def test_dqn_takes_the_zoos_network():
    arguments, n_envs, n_timesteps = model_arguments(zoo_entry("dqn")[0])
    assert (n_envs, n_timesteps) == (1, 50_000)
    assert arguments["policy_kwargs"] == {"net_arch": [256, 256]}


def test_a_longer_dqn_budget_keeps_its_exploration_schedule_in_steps():
    """dqn_4x trains four times as long and no otherwise: epsilon still decays over the first
    8,000 steps (16 % of 50,000). PPO's schedules are fractions of the training: refused."""
    arguments, _, n_timesteps = model_arguments(zoo_entry("dqn")[0], budget_factor=4)
    assert n_timesteps == 200_000
    assert arguments["exploration_fraction"] * n_timesteps == pytest.approx(8_000)
    with pytest.raises(ValueError, match="lin_ schedules"):
        model_arguments(zoo_entry("ppo")[0], budget_factor=4)


def test_a_tasks_entry_is_rl_zoo3s_own_and_normalize_is_trains():
    """Acrobot-v1's PPO entry normalizes (train() wraps VecNormalize, not the model's argument);
    the MuJoCo tasks take rl-zoo3's v2 entries; DQN has none for a continuous action space."""
    entry = zoo_entry("ppo", "Acrobot-v1")[0]
    arguments, n_envs, n_timesteps = model_arguments(entry)
    assert entry["normalize"] and "normalize" not in arguments
    assert (n_envs, n_timesteps, arguments["n_steps"]) == (16, 1_000_000, 256)
    assert zoo_entry("ppo", "InvertedPendulum-v5")[0]["n_steps"] == 32
    assert zoo_entry("ppo", "InvertedDoublePendulum-v5")[0]["batch_size"] == 512
    assert zoo_entry("dqn", "InvertedPendulum-v5") is None
