"""The pure core against hand computations and the paper's own calibration numbers."""

import math

import numpy as np
import pytest

from clnn_ros.core.encoder import Encoder
from clnn_ros.core.episode import angle_grid, run_trial, seed_setup
from clnn_ros.core.optimal import optimal_weights
from clnn_ros.core.params import ParamError, Params, params_from_strings
from clnn_ros.core.physics import (CONTINUE, FAIL_POSITION, CartPole, at_rest, cartpole_step,
                                   physics_constants)
from clnn_ros.core.random_stream import next_uniform
from clnn_ros.core.agent import RLNAgent, SuccessCounter
from clnn_ros.core.rln import NONE, PUNISH, REWARD


def state(theta_deg=0.0, x_dot=0.0):
    return (0.0, x_dot, theta_deg, 0.0)


@pytest.mark.parametrize("theta, interval", [
    (-12.0, 0), (-6.0 - 1e-12, 0), (-6.0, 1), (-1.0 - 1e-12, 1), (-1.0, 2), (-1e-12, 2),
    (0.0, 3), (1.0 - 1e-12, 3), (1.0, 4), (6.0 - 1e-12, 4), (6.0, 5), (12.0, 5)])
def test_angle_intervals_are_lower_inclusive(theta, interval):
    encoder = Encoder.from_params(Params(nsv=1))
    expected = np.zeros(6, dtype=np.uint8)
    expected[interval] = 1
    np.testing.assert_array_equal(encoder.spikes(state(theta)), expected)


@pytest.mark.parametrize("edge", [5.0, 0.5])
@pytest.mark.parametrize("factor, interval", [(-2.0, 0), (-1.0, 1), (-0.999, 1), (0.999, 1),
                                              (1.0, 2), (3.0, 2)])
def test_velocity_intervals_follow_the_edge(edge, factor, interval):
    encoder = Encoder.from_params(Params(nsv=2, velocity_edge=edge))
    spikes = encoder.spikes(state(0.5, factor * edge))
    assert spikes.sum() == 2 and spikes[3] == 1  # one angle input (0.5 deg -> [0,1)), one velocity
    assert spikes[6 + interval] == 1


def test_encoder_labels_name_each_input():
    labels = Encoder.from_params(Params(nsv=2)).labels()
    assert labels[2] == "pole_angle[-1,0)deg"
    assert labels[6] == "cart_velocity[-inf,-5)m/s" and labels[8] == "cart_velocity[5,inf)m/s"


def test_wta_tie_is_broken_by_fractional_weights():
    p = Params(nsv=1)
    weights = np.full((2, 3, 6), 4.5)
    weights[0, 2, 3] = 4.6  # neuron 0: segment 2 has the largest exact weight on input 3
    weights[1, 1, 3] = 4.7  # neuron 1: segment 1, and larger than neuron 0's best
    agent = RLNAgent(p, weights)
    spikes = np.eye(6, dtype=np.uint8)[3]
    assert agent.infer(spikes) == (1, (2, 1))  # all ceil to 5: only the fractions decide
    agent_by_index = RLNAgent(p.replace(tie_break="index"), weights)
    assert agent_by_index.infer(spikes) == (0, (0, 0))


def test_random_ties_draw_dendrite_0_then_1_then_the_network():
    agent = RLNAgent(Params(tie_break="random"), np.full((2, 3, 6), 4.5), seed=7)
    stream = np.array([7], dtype=np.uint64)
    with np.errstate(over="ignore"):
        expected = [int(next_uniform(stream) * n) for n in (3, 3, 2)]  # all tied at every level
    neuron, segments = agent.infer(np.eye(6, dtype=np.uint8)[0])
    assert (*segments, neuron) == tuple(expected)
    np.testing.assert_array_equal(agent.random_state, stream)


def test_ceiled_response_beats_fractions():
    weights = np.full((2, 3, 6), 4.9)
    weights[1, 0, 0] = 5.01  # ceil 6 wins over many 4.9s (ceil 5) despite smaller fractions
    assert RLNAgent(Params(), weights).infer(np.eye(6, dtype=np.uint8)[0])[0] == 1


def test_punishment_update_by_hand():
    p = Params(omega=4, punish=0.5, sigma=100)
    weights = np.full((2, 3, 6), 4.5)
    weights[0, 0, 3] = 4.9  # the path: input 3 always drives neuron 0, segment 0
    weights[0, 1, 2] = 4.9  # input 2 drives neuron 0, segment 1
    agent = RLNAgent(p, weights)
    eye = np.eye(6, dtype=np.uint8)
    assert agent.act(eye[2])[0] == 0  # tick 1: c-(0,1,2) = 4
    agent.learn(NONE)  # decays to 3
    assert agent.act(eye[3])[0] == 0  # tick 2: c-(0,0,3) = 4
    agent.learn(PUNISH)  # w -= pi c / omega: 0.5*4/4 = 0.5 at the head, 0.5*3/4 = 0.375 before
    expected = weights.copy()
    expected[0, 0, 3] -= 0.5
    expected[0, 1, 2] -= 0.375
    np.testing.assert_array_equal(agent.weights, expected)
    np.testing.assert_array_equal(agent.punish_counter[0, :2, 2:4], [[0, 3], [2, 0]])


def test_reward_update_by_hand():
    p = Params(sigma=4, rho_plus=0.25, rho_minus=0.125, omega=100)
    weights = np.full((2, 3, 6), 4.5)
    weights[1, 2, 5] = 4.9
    agent = RLNAgent(p, weights)
    counter = SuccessCounter(p)
    spikes = np.eye(6, dtype=np.uint8)[5]
    kinds = []
    for _ in range(4):
        assert agent.act(spikes)[0] == 1
        kinds.append(counter.outcome(terminated=False, reward=1.0))
        agent.learn(kinds[-1])
    assert kinds == [NONE, NONE, NONE, REWARD]
    # only segment (1, 2) was on the path; c+ = sigma at the head: +0.25*4/4 where e = 1,
    # -0.125*4/4 on the synapses whose input did not spike
    expected = weights.copy()
    expected[1, 2, 5] += 0.25
    expected[1, 2, :5] -= 0.125
    np.testing.assert_array_equal(agent.weights, expected)


@pytest.mark.parametrize("e_flag, older_e", [("latched", 5), ("live", 4)])
def test_reward_e_flags_latched_at_tagging_or_live(e_flag, older_e):
    """e latched: each segment's own spikes when it was tagged; live: the latest tick's spikes."""
    p = Params(sigma=2, rho_plus=0.25, rho_minus=0.125, omega=100, e_flag=e_flag)
    weights = np.full((2, 3, 6), 4.5)
    weights[1, 0, 5] = 4.9  # input 5 -> (1, 0)
    weights[1, 1, 4] = 4.9  # input 4 -> (1, 1)
    agent = RLNAgent(p, weights)
    eye = np.eye(6, dtype=np.uint8)
    agent.act(eye[5])
    agent.learn(NONE)
    agent.act(eye[4])
    agent.learn(REWARD)
    others = [i for i in range(6) if i != older_e]
    expected = weights.copy()
    expected[1, 1, 4] += 0.25  # head, c+ = 2: +0.25 * 2/2
    expected[1, 1, [0, 1, 2, 3, 5]] -= 0.125
    expected[1, 0, older_e] += 0.125  # one tick older, c+ = 1
    expected[1, 0, others] -= 0.0625
    np.testing.assert_array_equal(agent.weights, expected)


@pytest.mark.parametrize("tagging, tagged", [("winner", [[0, 0, 0], [0, 0, 5]]),
                                             ("both_neurons", [[5, 0, 0], [0, 0, 5]])])
def test_tagging_marks_the_action_path_or_both_neurons(tagging, tagged):
    p = Params(sigma=5, tagging=tagging)
    weights = np.full((2, 3, 6), 4.5)
    weights[1, 2, 3] = 4.9  # neuron 1 wins through segment 2; neuron 0's winner is segment 0
    agent = RLNAgent(p, weights)
    assert agent.act(np.eye(6, dtype=np.uint8)[3]) == (1, 2)
    np.testing.assert_array_equal(agent.reward_counter, tagged)
    np.testing.assert_array_equal(agent.punish_counter[:, :, 3], np.array(tagged) * p.omega // 5)


@pytest.mark.parametrize("success_counter, second_trial_kinds", [
    ("per_trial", [NONE, NONE, REWARD]), ("carry", [REWARD, NONE, NONE])])
def test_success_counter_per_trial_or_carried(success_counter, second_trial_kinds):
    counter = SuccessCounter(Params(sigma=3, success_counter=success_counter))
    counter.begin_trial()
    assert [counter.outcome(False, 1.0) for _ in range(2)] == [NONE, NONE]
    assert counter.outcome(True, 1.0) == PUNISH
    counter.begin_trial()
    assert [counter.outcome(False, 1.0) for _ in range(3)] == second_trial_kinds  # 2 carried


def test_weights_saturate_at_zero_and_wmax():
    p = Params(omega=1, punish=100.0)
    agent = RLNAgent(p, np.full((2, 3, 6), 4.5))
    agent.act(np.eye(6, dtype=np.uint8)[0])
    agent.learn(PUNISH)
    assert agent.weights.min() == 0.0 and agent.weights.max() == 4.5


def test_counters_restart_each_trial():
    p = Params()
    agent = RLNAgent(p, np.full((2, 3, 6), 4.5))
    agent.act(np.eye(6, dtype=np.uint8)[0])
    agent.begin_trial(0)
    agent.learn(PUNISH)
    assert np.all(agent.weights == 4.5)


def test_rerandomization_redraws_weights_at_its_trials_only():
    p = Params(rerandomize_every=3, rerandomize_fraction=0.5, rerandomize_range=2.0)
    agent = RLNAgent(p, np.full((2, 3, 6), 1.0))
    for trial in (0, 1, 2, 4):  # not due (and never at the episode's first trial)
        agent.begin_trial(trial)
    assert np.all(agent.weights == 1.0)
    agent.begin_trial(3, learn=False)  # a frozen agent keeps its weights
    assert np.all(agent.weights == 1.0)
    agent.begin_trial(3)
    redrawn = agent.weights != 1.0
    assert 0 < redrawn.sum() < redrawn.size
    assert np.all((agent.weights[redrawn] >= p.w_base)
                  & (agent.weights[redrawn] < p.w_base + p.rerandomize_range))


def test_calibration_b_constant_force_leaves_track_in_32_steps():
    constants = physics_constants(Params(physics="paper"))
    for force in (10.0, -10.0):
        s, steps = (0.0, 0.0, 0.0, 0.0), 0
        while True:
            *s, status = cartpole_step(*s, force, constants)
            if status != CONTINUE:
                break
            steps += 1
        assert (steps, status) == (32, FAIL_POSITION)
        assert abs(s[2]) < 12  # the pole has not fallen yet


def test_correct_physics_drops_the_pole_about_eight_times_faster():
    def fall_steps(physics):
        env, steps = CartPole(Params(physics=physics)), 0
        env.reset(at_rest(1.5))
        while env.step_force(0.0) == CONTINUE:
            steps += 1
        return steps
    paper, correct = fall_steps("paper"), fall_steps("correct")
    assert 150 < paper < 400 and 20 < correct < 60
    assert paper / correct == pytest.approx(math.sqrt(180 / math.pi), rel=0.15)


def test_sign_convention_plus_force_tilts_pole_back():
    env = CartPole(Params())
    env.reset(at_rest(0.0))
    env.step(1)
    x, x_dot, theta, theta_dot = env.state
    assert x_dot > 0 and theta_dot < 0


def test_optimal_1sv_weights_hold_the_pole_near_zero():
    p = Params(nsv=1)
    agent = RLNAgent(p, optimal_weights(1))
    env, encoder, counter = CartPole(p), Encoder.from_params(p), SuccessCounter(p)
    angles = []
    env.reset(at_rest(angle_grid(p)[16]))
    steps, status = run_trial(agent, counter, env, encoder, p, learn=False,
                              trace=lambda s: angles.append(s[2]))
    assert (steps, status) == (10_000, CONTINUE)
    assert max(abs(a) for a in angles) < 1.5


def test_optimal_weights_patterns():
    w1, w2 = optimal_weights(1), optimal_weights(2)
    assert w1.shape == (2, 3, 6) and w2.shape == (2, 9, 9)
    assert np.all(w1.sum(axis=2) == 8) and np.all(w2.sum(axis=2) == 16)
    # every 2-SV input pattern (angle, velocity) is owned by exactly one segment of one neuron
    owners = {(int(np.flatnonzero(seg[:6])[0]), int(np.flatnonzero(seg[6:])[0]))
              for neuron in w2 for seg in neuron}
    assert len(owners) == 18


def test_seed_protocol():
    p = Params()
    weights, angles = seed_setup(7, p)
    rng = np.random.default_rng(7)
    np.testing.assert_array_equal(weights, 4.5 + rng.uniform(0, 1 / 128, size=(2, 3, 6)))
    grid = -1.5 + 3 * np.arange(32) / 31
    np.testing.assert_array_equal(angles[:32], grid[rng.permutation(32)])
    assert len(angles) == 512
    assert all(sorted(angles[k:k + 32]) == sorted(grid) for k in range(0, 512, 32))


@pytest.mark.parametrize("changes, message", [
    (dict(sigma=-1), "sigma must be a positive integer"),
    (dict(omega=0), "omega must be a positive integer"),
    (dict(w_max=4.0), "must not exceed w_max"),
    (dict(physics="quantum"), "physics must be one of"),
    (dict(nsv=5), "nsv must be 1, 2, 3 or 4"),
    (dict(state_vars="pole_angle,pole_tilt"), "state_vars: unknown 'pole_tilt'"),
    (dict(state_vars="pole_angle,pole_angle"), "names a variable twice"),
    (dict(state_vars="pole_angle", nsv=2), "nsv (2) must be the number of state_vars (1"),
    (dict(position_edges_m="1,-1"), "position_edges_m must be strictly increasing"),
    (dict(angular_velocity_edges_deg_per_s="fast"), "angular_velocity_edges_deg_per_s must be"),
    (dict(decay_counters="sometimes"), "decay_counters must be one of"),
    (dict(first_action="jump"), "first_action must be one of"),
    (dict(punish_timing="later"), "punish_timing must be one of"),
    (dict(inference="fuzzy"), "inference must be one of"),
    (dict(velocity_edge=-1.0), "velocity_edge must be > 0"),
    (dict(rho_plus=float("nan")), "rho_plus must be a finite number"),
    (dict(tie_break="coin"), "tie_break must be one of"),
    (dict(segments=0), "segments must be an integer from 1 to 256"),
    (dict(trials=2.5), "trials must be a positive integer"),
    (dict(unknown_thing=1), "unknown parameter"),
])
def test_bad_parameters_give_one_clear_line(changes, message):
    with pytest.raises(ParamError) as error:
        Params().replace(**changes)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_parameters_from_text():
    p = params_from_strings({"sigma": "128", "velocity_edge": "0.5", "physics": "correct"})
    assert (p.sigma, p.velocity_edge, p.physics) == (128, 0.5, "correct")
    with pytest.raises(ParamError, match="sigma must be an integer, got 'many'"):
        params_from_strings({"sigma": "many"})


def test_agent_refuses_weights_out_of_range():
    with pytest.raises(ValueError, match="shape"):
        RLNAgent(Params(), np.zeros((2, 3, 5)))
    with pytest.raises(ValueError, match=r"\[0, w_max"):
        RLNAgent(Params(), np.full((2, 3, 6), 9.0))


@pytest.mark.parametrize("tie_break", ["exact", "index", "random"])
def test_kept_decisions_are_those_of_the_current_weights(tie_break):
    # The agent keeps its decision for each input pattern until the weights change: after
    # punishments, rewards, re-randomizations and a loaded state, every decision is the one the
    # rule makes anew (a twin agent without kept decisions draws the same random ties).
    p = Params(nsv=2, sigma=3, omega=2, tie_break=tie_break, rerandomize_every=4,
               rerandomize_fraction=0.3, rerandomize_range=2.0)
    weights, _ = seed_setup(5, p)
    agent, twin = RLNAgent(p, weights, seed=5), RLNAgent(p, weights, seed=5)
    encoder, draws = Encoder.from_params(p), np.random.default_rng(0)
    patterns = [encoder.spikes(state(theta, velocity)) for theta in (-3.0, -0.5, 0.5, 3.0)
                for velocity in (-9.0, 0.0, 9.0)]
    kept = 0
    for tick in range(600):
        if tick % 50 == 0:
            agent.begin_trial(tick // 50)
            twin.begin_trial(tick // 50)
        if tick == 300:
            agent.load_state(RLNAgent(p, seed_setup(6, p)[0]).state())
            twin.load_state(agent.state())
        spikes = patterns[draws.integers(len(patterns))]
        kept += agent._decisions.get(np.flatnonzero(spikes).tobytes()) is not None
        twin._decisions.clear()
        assert agent.act(spikes) == twin.act(spikes), tick
        kind = (PUNISH, REWARD, *[NONE] * 6)[draws.integers(8)]
        agent.learn(kind)
        twin.learn(kind)
        np.testing.assert_array_equal(agent.weights, twin.weights)
    assert (kept > 100) == (tie_break != "random")  # the decisions were kept between changes


def test_agent_weights_change_only_by_the_rule():
    agent = RLNAgent(Params(), np.full((2, 3, 6), 4.5))
    with pytest.raises(ValueError, match="read-only"):
        agent.weights[0, 0, 0] = 1.0
