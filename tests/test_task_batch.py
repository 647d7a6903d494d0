"""The task batch engine (clnn_ros.task_batch) and its compiled steps
(clnn_ros.tasks.compiled) equal Gymnasium's own steps and the core's task episode, bit
for bit."""

from __future__ import annotations

import csv
import importlib.util
import json
import random
from pathlib import Path

import numpy as np
import pytest

from clnn_ros.core.encoder import Encoder
from clnn_ros.core.episode import seed_setup
from clnn_ros.core.rule import Rule
from clnn_ros.core.task_episode import run_task_episode
from clnn_ros.task_batch import compiles, run_compiled_task_episode
from clnn_ros.tasks import compiled
from clnn_ros.tasks.gymnasium_task import make, task_params


@pytest.mark.parametrize("name", sorted(compiled.COMPILED))
def test_a_compiled_step_is_gymnasiums_bit_for_bit(name):
    """Random actions from Gymnasium's own starts: every step's observation, reward and
    termination alike, and the state behind them (the Acrobot's squares through libm's pow: as
    x * x, 11 of these 30 trajectories part)."""
    import gymnasium

    task, _ = make(f"gymnasium:{name}")
    env = gymnasium.make(name)
    engine = compiled.CompiledTask(task, env)
    mujoco = engine.code in compiled.MUJOCO
    given = [a.value if mujoco else int(a.value) for a in task.actions]
    actions = np.random.default_rng(1)
    values, terminations = np.empty(env.observation_space.shape[0]), 0
    for trajectory in range(30):
        observation, _ = env.reset(seed=trajectory)
        state = engine.start_state(env)
        compiled.begin(engine.code, state, engine.sim)
        compiled.observe(engine.code, state, engine.sim, values)
        assert values.tolist() == observation.tolist()
        for _ in range(500):
            action = int(actions.integers(len(given)))
            observation, reward, terminated, truncated, _ = env.step(
                np.array([given[action]], dtype=env.action_space.dtype)
                if mujoco else given[action])
            assert compiled.step(engine.code, state, engine.sim, engine.forces,
                                 action) == (reward, terminated)
            compiled.observe(engine.code, state, engine.sim, values)
            assert values.tolist() == observation.tolist()
            if mujoco:  # MuJoCo's data, not only what it shows
                assert engine.sim[2].tolist() == env.unwrapped.data.qpos.tolist()
                assert engine.sim[3].tolist() == env.unwrapped.data.qvel.tolist()
            else:
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
    ("gymnasium:Acrobot-v1", {"reward_mapping": "shaped"}),
    ("gymnasium:MountainCar-v0", {}),
    ("gymnasium:MountainCar-v0", {"omega": "16", "variable_edges": "position:-0.5;velocity:0",
                                  "segments": "2"}),
    ("gymnasium:InvertedPendulum-v5", {}),
    ("gymnasium:InvertedPendulum-v5", {"actions": "-1,0.3,1", "tie_break": "random"}),
    ("gymnasium:InvertedDoublePendulum-v5", {}),
    ("gymnasium:InvertedDoublePendulum-v5", {"reward_mapping": "shaped", "sigma": "4"}),
])
def test_the_task_batch_engine_is_the_cores_episode_bit_for_bit(name, changes):
    actions = changes.get("actions")  # a Box action space's declared values (float32 there)
    task, _ = make(name, actions)
    assert compiles(task)
    p = task_params(task, {"trials": "8", "sigma": "32", "omega": "64",
                           **{k: v for k, v in changes.items() if k != "actions"}})
    ours = run_compiled_task_episode(7, p, task, make(name, actions)[1])
    core = run_task_episode(7, p, task, make(name, actions)[1])
    assert ours.steps.tolist() == core.steps.tolist()
    assert ours.returns.tolist() == core.returns.tolist()
    assert ours.terminated.tolist() == core.terminated.tolist()
    assert np.array_equal(ours.final_weights, core.final_weights)
    assert not np.array_equal(core.final_weights, seed_setup(7, p)[0])  # it learned
    frozen = run_compiled_task_episode(7, p, task, make(name, actions)[1], learn=False)
    assert frozen.steps.tolist() == run_task_episode(7, p, task, make(name, actions)[1],
                                                     learn=False).steps.tolist()


def test_only_the_compiled_steps_compile():
    assert not compiles(make("gymnasium:CartPole-v1")[0])


def test_learn_a_task_with_its_preset(tmp_path, capsys):
    """`learn --task ID --preset NAME`: the preset's values over the task's, an option over
    them; the seeds' episodes are the core's (the engine's, shown equal above)."""
    from clnn_ros.core.presets import preset_values
    from clnn_ros.reproduce.__main__ import main

    assert main(["learn", "--task", "gymnasium:Acrobot-v1", "--preset", "acrobot_v1",
                 "--option", "sigma=32", "--seeds", "3", "--trials", "5", "--workers", "1",
                 "--out", str(tmp_path)]) == 0
    with np.load(tmp_path / "final_weights_Acrobot-v1.npz") as saved:
        task, env = make("gymnasium:Acrobot-v1")
        p = task_params(task, {**preset_values("acrobot_v1"), "sigma": "32", "trials": "5"})
        assert json.loads(str(saved["params"])) == json.loads(json.dumps(p.to_dict()))
        assert p.state_vars == ("theta1_dot",) and p.omega == 100 and p.sigma == 32
        core = run_task_episode(3, p, task, env)
        assert saved["steps"][0].tolist() == core.steps.tolist()
        np.testing.assert_array_equal(saved["final_weights"][0], core.final_weights)


def test_run_all_refuses_another_tasks_preset_in_one_line():
    from clnn_ros import run_all

    for argv, other in ((["--preset", "acrobot_v1"], "the cart-pole"),
                        (["--env", "gymnasium:MountainCar-v0", "--preset", "acrobot_v1"],
                         "gymnasium:MountainCar-v0")):
        with pytest.raises(ValueError, match=f"preset acrobot_v1 is for --task "
                                             f"gymnasium:Acrobot-v1 .*, not {other}$"):
            run_all.build_parameters(run_all.parse_args([*argv, "--no-record"]))


def load_script(name: str):
    path = Path(__file__).parents[1] / "scripts" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_preset_search_draws_distinct_candidates_and_ranks_solving_first():
    """scripts/task_search.py: a fixed draw of distinct candidates of each task's space (all of
    them valid Params for the task), ranked by seeds solved, then fewer steps to solve."""
    search = load_script("task_search")
    for task_name, space in search.SPACES.items():
        drawn = search.candidates(space, 12, random.Random(46))
        assert len(drawn) == 12 and all(drawn.count(c) == 1 for c in drawn)
        assert drawn == search.candidates(space, 12, random.Random(46))
        task, _ = make(task_name)
        for candidate in drawn:
            task_params(task, {k: v for k, v in candidate.items() if v})
    rows = [[8, 3, "200", "30000", "-150.0", "-120.0"], [8, 5, "300", "40000", "-140.0", "-110.0"],
            [8, 5, "250", "35000", "-130.0", "-105.0"], [8, 0, "-", "-", "-100.0", "-90.0"]]
    assert sorted(range(4), key=lambda k: search.rank(rows[k])) == [2, 1, 0, 3]


@pytest.mark.parametrize("task_name, actions, edges", [
    ("gymnasium:MountainCar-v0", None, "position:-0.9,-0.5,-0.2;velocity:-0.005,0,0.005"),
    ("gymnasium:InvertedPendulum-v5", "-1,1", "hinge_angle:-0.01,0,0.01;slider_velocity:0"),
])
def test_a_table_written_into_weights_is_what_the_network_plays(task_name, actions, edges):
    """scripts/encoding_capacity.py: any table pattern -> action, written into the weights (with
    spare segments too), is read back by the core's inference pattern for pattern."""
    capacity = load_script("encoding_capacity")
    task, _ = make(task_name, actions)
    names = ",".join(part.split(":")[0] for part in edges.split(";"))
    p = task_params(task, {"state_vars": names, "variable_edges": edges})
    _, _, offsets = Encoder.from_params(p, task.names, task.units).arrays
    radix = [int(b - a) for a, b in zip(offsets, [*offsets[1:], p.n_inputs])]
    rng = np.random.default_rng(46)
    for spare in (0, 5):
        table = tuple(int(a) for a in rng.integers(0, p.n_actions, int(np.prod(radix))))
        weights = capacity.table_weights(table, radix, offsets, p.n_actions, p.n_inputs,
                                         p.w_max, len(table) + spare)
        assert capacity.played_table(weights, radix, offsets, Rule.from_params(p)) == table


def test_the_encoding_capacity_finds_acrobots_policy_and_refuses_a_bad_table(tmp_path, capsys):
    """Acrobot-v1 with theta1_dot cut at 0: of its 9 tables the best is the one every seed of
    the preset learns (theta1_dot < 0: torque +1, else -1: actions 2, 0), above the threshold;
    and a --start that is no table of the encoding is one line and exit 2."""
    capacity = load_script("encoding_capacity")
    argv = ["gymnasium:Acrobot-v1", "--state-vars", "theta1_dot", "--edges", "theta1_dot:0",
            "--episodes", "5", "--preset", "acrobot_v1", "--learn", "20", "--learn-seeds",
            "128-129", "--csv", str(tmp_path / "capacity.csv")]
    assert capacity.main(argv) == 0
    with open(tmp_path / "capacity.csv") as f:
        row = next(csv.DictReader(f))
    assert row["search"] == "every table" and row["best table"] == "20"
    assert float(row["best mean return"]) >= -100 > float(row["one change away: best"])
    assert row["from the best table: last 100"] != "" and row["learning seeds"] == "2"
    # the control: the reversed table, written as strongly, is as far out of the rule's reach
    assert float(row["from the reversed table: last 100"]) < -100
    # written a little above the seed's own weights instead, the rule corrects it
    assert capacity.main([*argv[:-6], "--learn", "150", "--learn-seeds", "128-129", "--margin",
                          "0.05", "--csv", str(tmp_path / "margin.csv")]) == 0
    with open(tmp_path / "margin.csv") as f:
        row = next(csv.DictReader(f))
    assert row["table written"] == "+0.05 on the seed's"
    assert float(row["from the reversed table: last 100"]) >= -100
    capsys.readouterr()
    assert capacity.main([*argv[:5], "--start", "7"]) == 2
    error = capsys.readouterr().err
    assert error.startswith("encoding_capacity: error: --start 7: a table is 2 actions")
    assert error.count("\n") == 1
    assert capacity.main([*argv[:5], "--restarts", "0"]) == 2
    assert capsys.readouterr().err.startswith("encoding_capacity: error: --restarts 0: hill")


def test_the_linear_controller_probe_holds_the_pendulum_and_refuses_a_task_without_mujoco(
        tmp_path, capsys):
    """InvertedPendulum-v5: LQR from the finite-difference model holds all 1,000 steps, also
    quantized to the forces -1 and +1; a task without MuJoCo is one line and exit 2."""
    probe = load_script("linear_controller_probe")
    out = tmp_path / "linear.csv"
    assert probe.main(["gymnasium:InvertedPendulum-v5", "--levels=-1,1", "--seeds", "128-129",
                       "--csv", str(out)]) == 0
    with open(out) as f:
        rows = list(csv.DictReader(f))
    assert [(r["forces"], float(r["mean_steps"])) for r in rows] == [("", 1000.0),
                                                                      ("-1 1", 1000.0)]
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        probe.main(["gymnasium:Acrobot-v1"])
    error = capsys.readouterr().err
    assert exit_.value.code == 2 and error.count("\n") == 1
    assert error.startswith("linear_controller_probe: error: gymnasium:Acrobot-v1 is not a "
                            "MuJoCo task with one actuator")
