"""Any task: the agent with K actions, the reward mappings, the task description, the one trial
loop of every task, and Gymnasium's tasks as environments (no ROS)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clnn_ros.core.agent import RLNAgent, SuccessCounter
from clnn_ros.core.encoder import Encoder
from clnn_ros.core.episode import run_episode, seed_setup, trial_starts
from clnn_ros.core.params import ParamError, Params
from clnn_ros.core.physics import CartPole
from clnn_ros.core.rln import NONE, PUNISH, REWARD
from clnn_ros.core.task import CARTPOLE_TASK, Action, Task, Variable
from clnn_ros.core.task_episode import run_task_episode
from clnn_ros.tasks import gymnasium_task
from clnn_ros.tasks.gymnasium_task import GymnasiumEnvironment, make, task_params

TOY = Task("toy", (Variable("a"), Variable("b")),
           tuple(Action(str(k), k) for k in range(3)), max_steps=50)


def toy_params(**changes) -> Params:
    return TOY.params({"variable_edges": "a:0;b:-1,1"}, Params(**changes))


def winner(responses: list[tuple[float, float]]) -> int:
    """The WTA's winner by its definition: the largest ceiled response, then the largest exact
    sum, then the lowest index."""
    return max(range(len(responses)), key=lambda k: (*responses[k], -k))


def test_the_network_wta_over_k_neurons_is_the_definition():
    p = toy_params(segments=4)
    rng = np.random.default_rng(5)
    for _ in range(200):
        weights = rng.uniform(0, p.w_max, size=(3, 4, p.n_inputs))
        spikes = Encoder.from_params(p, TOY.names).spikes(rng.normal(size=2) * 2)
        active = np.flatnonzero(spikes)
        segments = [winner([(sum(math.ceil(w) for w in weights[n, s, active]),
                             weights[n, s, active].sum()) for s in range(4)]) for n in range(3)]
        neuron = winner([(sum(math.ceil(w) for w in weights[n, segments[n], active]),
                          weights[n, segments[n], active].sum()) for n in range(3)])
        assert RLNAgent(p, weights).infer(spikes) == (neuron, tuple(segments))


def test_exploring_with_k_neurons_picks_each_other_neuron_alike():
    p = toy_params(explore=1.0)
    agent = RLNAgent(p, seed_setup(0, p)[0], seed=3)
    spikes = Encoder.from_params(p, TOY.names).spikes((0.5, 0.0))
    chosen = agent.infer(spikes)[0]
    acted = [agent.act(spikes)[0] for _ in range(3000)]
    counts = np.bincount(acted, minlength=3)
    assert counts[chosen] == 0
    assert all(900 < c < 2100 for k, c in enumerate(counts) if k != chosen), counts


def test_tagging_both_neurons_tags_every_neurons_winner_with_k_neurons():
    p = toy_params(tagging="both_neurons")
    agent = RLNAgent(p, seed_setup(1, p)[0])
    spikes = Encoder.from_params(p, TOY.names).spikes((0.5, 0.0))
    _, segments = agent.infer(spikes)
    agent.act(spikes)
    tagged = agent.reward_counter
    assert [int(tagged[n, s]) for n, s in enumerate(segments)] == [p.sigma] * 3
    assert int(tagged.sum()) == 3 * p.sigma


def test_the_goal_mapping_rewards_the_goal_and_punishes_every_omega_steps_without_it():
    counter = SuccessCounter(Params(reward_mapping="goal", omega=3, sigma=2))
    kinds = [counter.outcome(False, -1.0) for _ in range(7)]
    assert kinds == [NONE, NONE, PUNISH, NONE, NONE, PUNISH, NONE]
    assert counter.outcome(True, -1.0) == REWARD
    paper = SuccessCounter(Params(omega=3, sigma=2))
    assert [paper.outcome(False, 1.0) for _ in range(4)] == [NONE, REWARD, NONE, REWARD]
    assert paper.outcome(True, 1.0) == PUNISH


def test_the_shaped_mapping_signals_the_sign_of_the_rewards_since_the_last_signal():
    counter = SuccessCounter(Params(task="gymnasium:LunarLander-v3", n_actions=4,
                                    reward_mapping="shaped", sigma=3, omega=100))
    counter.begin_trial()
    rewards = [2.0, -1.0, 0.5,  -3.0, 1.0, 1.0,  0.25, -0.25, 0.0,  5.0, -100.0]
    kinds = [counter.outcome(False, r) for r in rewards[:-1]]
    assert kinds == [NONE, NONE, REWARD, NONE, NONE, PUNISH, NONE, NONE, NONE, NONE]
    assert counter.outcome(True, rewards[-1]) == PUNISH  # 5 - 100: a crash after a good step
    counter.begin_trial()  # a trial starts with nothing summed
    assert counter.outcome(False, -1.0) == NONE
    counter.begin_trial()
    assert counter.outcome(True, 100.0) == REWARD  # a landing
    counter.begin_trial()
    assert counter.outcome(True, 0.0) == PUNISH  # an end that gained nothing is no success


@pytest.mark.parametrize("changes, message", [
    ({"success_counter": "carry"}, "reward_mapping shaped sums each trial's own rewards: "
                                   "success_counter must be per_trial"),
    ({"task": "cartpole", "n_actions": 2},
     "reward_mapping shaped reads a task's rewards, and the cart-pole's are the same on every "
     "step: use failure")])
def test_the_shaped_mapping_is_refused_where_it_cannot_read_a_trials_rewards(changes, message):
    with pytest.raises(ParamError) as error:
        Params(**{"task": "gymnasium:LunarLander-v3", "n_actions": 4,
                  "reward_mapping": "shaped", **changes})
    assert str(error.value) == message


@pytest.mark.parametrize("changes, message", [
    (dict(n_actions=3), "the cart-pole has 2 actions"),
    (dict(task="other", n_actions=1), "n_actions must be an integer from 2"),
    (dict(task="other", n_actions=True), "n_actions must be an integer from 2"),
    (dict(variable_edges="a:1,0"), "variable_edges of a must be strictly increasing"),
    (dict(variable_edges="a"), "variable_edges must be name:edges"),
    (dict(variable_edges="pole_angle:0"), "pole_angle is a cart-pole variable"),
    (dict(variable_edges="a:0;a:1"), "variable_edges names a twice"),
    (dict(variable_edges="a:0", state_vars="b"), "state_vars: unknown 'b'"),
    (dict(reward_mapping="sometimes"), "reward_mapping must be one of"),
])
def test_bad_task_values_are_one_line(changes, message):
    with pytest.raises(ParamError, match=message) as error:
        Params(**changes)
    assert "\n" not in str(error.value)


def test_variable_edges_as_text_round_trip_and_empty_text_is_none():
    from clnn_ros.core.params import variable_edges_text

    p = Params(variable_edges=(("a", (0.1, 2)), ("b", [-1])))
    assert p.variable_edges == (("a", (0.1, 2.0)), ("b", (-1.0,)))
    assert variable_edges_text(p.variable_edges) == "a:0.1,2.0;b:-1.0"
    assert Params(variable_edges=variable_edges_text(p.variable_edges)) == p
    assert Params(variable_edges="").variable_edges == ()
    assert Params(variable_edges=" ").variable_edges == ()


def test_a_task_refuses_params_that_do_not_fit_it():
    with pytest.raises(ParamError, match="variable_edges has no edges for b"):
        TOY.params({"variable_edges": "a:0"})
    with pytest.raises(ParamError, match="has 3 actions"):
        TOY.check(toy_params().replace(n_actions=4))
    with pytest.raises(ParamError, match="for task 'cartpole', not 'toy'"):
        TOY.check(Params())
    with pytest.raises(ParamError, match="no 'b'"):
        Encoder.from_params(toy_params(), ("a", "c"))


def test_the_encoder_labels_a_tasks_inputs_by_its_names_and_units():
    task = Task("t", (Variable("speed", "m/s"), Variable("gap", "m")), TOY.actions)
    p = task.params({"variable_edges": "speed:0;gap:1,2"})
    encoder = Encoder.from_params(p, task.names, task.units)
    assert encoder.labels() == ["speed[-inf,0)m/s", "speed[0,inf)m/s", "gap[-inf,1)m",
                                "gap[1,2)m", "gap[2,inf)m"]
    assert encoder.spikes((0.5, 1.5)).tolist() == [0, 1, 0, 1, 0]
    assert p.n_actions == 3 and p.state_vars == ("speed", "gap") and p.n_segments == 3


class PaperCartPole:
    """The core's cart-pole behind the task interface, at each trial's start of the seed."""

    def __init__(self, seed: int, p: Params):
        self.env, self.starts = CartPole(p), iter(trial_starts(seed, p)[0])

    def reset(self, seed):
        return self.env.reset(next(self.starts))

    def step(self, action):
        status = self.env.step(action)
        return self.env.state, 0.0, status != 0, False


@pytest.mark.parametrize("seed", [0, 3])
def test_a_tasks_episode_of_the_cart_pole_is_the_cart_poles_episode(seed):
    """One trial loop for every task: driven through the task interface, the paper's cart-pole
    gives the core's episode, trial by trial and in the final weights."""
    p = Params(trials=24, nsv=2, velocity_edge=0.28)
    ours = run_task_episode(seed, p, CARTPOLE_TASK, PaperCartPole(seed, p))
    core = run_episode(seed, p)
    assert (ours.steps - ours.terminated).tolist() == core.steps.tolist()
    assert ours.terminated.tolist() == (core.end_status != 0).tolist()
    assert np.array_equal(ours.final_weights, core.final_weights)


TASKS = {"CartPole-v1": (2, 500, 475.0), "Acrobot-v1": (3, 500, -100.0),
         "MountainCar-v0": (3, 200, -110.0), "LunarLander-v3": (4, 1000, 200.0),
         "InvertedPendulum-v5": (2, 1000, 950.0), "InvertedDoublePendulum-v5": (3, 1000, 9100.0)}


@pytest.mark.parametrize("name", TASKS)
def test_gymnasiums_tasks_are_tasks_and_their_episodes_repeat_for_a_seed(name):
    task, env = make(f"gymnasium:{name}")
    assert (len(task.actions), task.max_steps, task.reward_threshold) == TASKS[name]
    p = task_params(task, {"trials": "3"})
    first = run_task_episode(7, p, task, env)
    again = run_task_episode(7, p, task, make(f"gymnasium:{name}")[1])
    assert first.steps.tolist() == again.steps.tolist() and first.returns.tolist() == \
        again.returns.tolist()
    assert np.array_equal(first.final_weights, again.final_weights)
    assert first.final_weights.shape[0] == len(task.actions)
    assert np.all((first.steps >= 1) & (first.steps <= task.max_steps))


def test_a_box_action_space_takes_declared_values():
    task, env = make("gymnasium:InvertedPendulum-v5", actions="-3,0,3")
    assert task.action_labels == ("-3", "0", "3")
    assert env._given[2].tolist() == [3.0]


@pytest.mark.parametrize("name, actions, message", [
    ("gymnasium:NoSuchTask-v0", None, "gymnasium:NoSuchTask-v0: "),
    ("gymnasium:FrozenLake-v1", None, "not a 1-D Box"),
    ("gymnasium:Pendulum-v1", None, "declare the values the agent may apply"),
    ("gymnasium:Pendulum-v1", "-1,9", r"in \[-2, 2\]"),
    ("gymnasium:Pendulum-v1", "1,1", "distinct"),
    ("gymnasium:Pendulum-v1", "a,b", "numbers separated by commas"),
    ("gymnasium:Acrobot-v1", "-1,1", "declares values of a Box action space only"),
    ("Acrobot-v1", None, "is named gymnasium:ID"),
])
def test_a_task_this_learner_cannot_take_is_refused_in_one_line(name, actions, message):
    with pytest.raises(ParamError, match=message) as error:
        make(name, actions)
    assert "\n" not in str(error.value)


def test_an_observation_a_node_cannot_handle_is_refused_naming_the_task():
    task, env = make("gymnasium:MountainCar-v0")
    with pytest.raises(ParamError, match="gymnasium:MountainCar-v0: an observation must be 2 "):
        env._checked([0.1, float("nan")])
    with pytest.raises(ParamError, match="must be 2 finite numbers, got"):
        GymnasiumEnvironment(task, env.env)._checked([0.1, 0.2, 0.3])


def test_an_unknown_tasks_components_are_numbered():
    task, _ = make("gymnasium:Pendulum-v1", actions="-2,2")
    assert task.names == ("x0", "x1", "x2") and task.reward_threshold is None
    assert task.variables[2].high == pytest.approx(8.0)
    assert gymnasium_task.env_id(task.name) == "Pendulum-v1"


def test_learn_a_gymnasium_task_from_the_command_line(tmp_path, capsys):
    from clnn_ros.reproduce.__main__ import main

    assert main(["learn", "--task", "gymnasium:MountainCar-v0", "--seeds", "0,2", "--trials", "3",
                 "--option", "sigma=64", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "solved gymnasium:MountainCar-v0 (last 100 returns averaging -110 or more): 0 of 2" \
        in out
    rows = (tmp_path / "learn_MountainCar-v0.csv").read_text().splitlines()
    summary = (tmp_path / "learn_MountainCar-v0.md").read_text()
    assert "| 2 |" in summary and "![learning curve](learn_MountainCar-v0.png)" in summary
    assert (tmp_path / "learn_MountainCar-v0.png").read_bytes().startswith(b"\x89PNG")
    assert rows[0] == "seed,trial,steps,return,terminated" and len(rows) == 1 + 2 * 3
    task, env = make("gymnasium:MountainCar-v0")
    core = run_task_episode(2, task_params(task, {"trials": "3", "sigma": "64"}), task, env)
    assert rows[4:] == [f"2,{t},{core.steps[t]},{float(core.returns[t])!r},"
                        f"{int(core.terminated[t])}"
                        for t in range(3)]
    # each seed's result is kept: a second run runs none and writes the same
    stored = sorted((tmp_path / "runs").iterdir())
    assert len(stored) == 2
    mtimes = [path.stat().st_mtime_ns for path in stored]
    assert main(["learn", "--task", "gymnasium:MountainCar-v0", "--seeds", "0,2", "--trials", "3",
                 "--option", "sigma=64", "--out", str(tmp_path), "--workers", "1"]) == 0
    assert [path.stat().st_mtime_ns for path in sorted((tmp_path / "runs").iterdir())] == mtimes
    assert (tmp_path / "learn_MountainCar-v0.csv").read_text().splitlines() == rows


@pytest.mark.parametrize("argv, message", [
    (["--task", "gymnasium:Acrobot-v1", "--physics", "correct"], "--physics is for the cart-pole"),
    (["--task", "gymnasium:Acrobot-v1", "--preset", "escape"],
     "preset escape is for the cart-pole, not gymnasium:Acrobot-v1"),
    (["--task", "gymnasium:MountainCar-v0", "--preset", "acrobot_v1"],
     "preset acrobot_v1 is for --task gymnasium:Acrobot-v1 (clnn-run --env gymnasium:Acrobot-v1), "
     "not gymnasium:MountainCar-v0"),
    (["--preset", "acrobot_v1"], "preset acrobot_v1 is for --task gymnasium:Acrobot-v1"),
    (["--actions=-1,1"], "--actions goes with --task gymnasium:ID"),
    (["--task", "Acrobot"], "a Gymnasium task is named gymnasium:ID"),
    (["--task", "gymnasium:Acrobot-v1", "--option", "n_actions=2"], "has 3 actions"),
    (["--task", "gymnasium:Acrobot-v1", "--workers", "0"], "--workers must be at least 1"),
])
def test_learn_refuses_what_a_task_cannot_take_in_one_line(argv, message, tmp_path, capsys):
    from clnn_ros.reproduce.__main__ import main

    assert main(["learn", *argv, "--trials", "1", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


def test_sweep_a_gymnasium_task_from_the_command_line(tmp_path, capsys):
    from clnn_ros.reproduce.__main__ import main

    assert main(["sweep", "--task", "gymnasium:CartPole-v1", "--param", "sigma=16,64",
                 "--seeds", "3", "--trials", "4", "--out", str(tmp_path)]) == 0
    assert "| sigma | seeds | solved |" in capsys.readouterr().out
    rows = (tmp_path / "sweep_CartPole-v1.csv").read_text().splitlines()
    assert rows[0] == ("sigma,seeds,solved,median episodes to solve,median steps to solve,"
                       "mean return,mean of the last 100")
    task, env = make("gymnasium:CartPole-v1")
    for row, sigma in zip(rows[1:], (16, 64)):
        core = run_task_episode(3, task_params(task, {"trials": "4", "sigma": str(sigma)}), task,
                                env)
        assert row == f"{sigma},1,0,-,-,{core.returns.mean():.1f},{core.returns.mean():.1f}"
    assert len(rows) == 3 and (tmp_path / "sweep_CartPole-v1.png").exists()
    assert "variable_edges=x:-0.8,0.8;" in (tmp_path / "sweep_CartPole-v1.md").read_text()


@pytest.mark.parametrize("name, actions, changes", [
    ("gymnasium:Acrobot-v1", None, {}),
    ("gymnasium:LunarLander-v3", None, {"tie_break": "random", "rerandomize_every": "2",
                                        "explore": "0.01", "tagging": "both_neurons"}),
    ("gymnasium:InvertedPendulum-v5", "-1,1", {}),  # each family Gymnasium builds differently
])
def test_the_compiled_kernels_are_the_cores_bit_for_bit(name, actions, changes):
    """The rule's costly functions compiled (what learn --task runs) give the core's episode."""
    from clnn_ros.batch import COMPILED_KERNELS

    task, _ = make(name, actions)
    p = task_params(task, {"trials": "6", "sigma": "32", "omega": "64", **changes})
    ours = run_task_episode(5, p, task, make(name, actions)[1], kernels=COMPILED_KERNELS)
    core = run_task_episode(5, p, task, make(name, actions)[1])
    assert ours.steps.tolist() == core.steps.tolist()
    assert ours.returns.tolist() == core.returns.tolist()
    assert np.array_equal(ours.final_weights, core.final_weights)
    assert not np.array_equal(core.final_weights, seed_setup(5, p)[0])  # it learned
