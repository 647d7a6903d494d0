"""The trial, episode and seed protocol (section 3.2).

An episode is `trials` (512) trials in which the network keeps learning. Trial: cart centred and
at rest, pole at rest at an initial angle from a grid of 32 evenly spaced angles in +-1.5 deg
(both ends included); it runs until the pole leaves +-12 deg, the cart leaves +-2.4 m, or
10,000 successful steps. Successful steps are the steps before the failing one.

Tick order: encode the state, infer and tag (the agent acts on the initial state first), apply
the force and step the physics, then the success counter turns the outcome into a reward kind
and the agent applies it.

Seed protocol (so that any two implementations can be compared trial by trial):
    rng = numpy.random.default_rng(seed)
    weights = w_base + rng.uniform(0, w_range, size=(K, q, n_inputs))   (K actions: 2 here)
    initial angles = successive grid[rng.permutation(32)], concatenated, cut to `trials`.

Protocol "gymnasium" (CartPole-v1's, as the RL field measures agents): trial k of seed s starts
where the (k+1)-th reset() of a CartPole-v1 seeded with reset(seed=STARTS_SEED + s) puts it,
i.e. numpy.random.default_rng(STARTS_SEED + s).uniform(-0.05, 0.05, (trials, 4)) row k (x m,
x_dot m/s, theta rad, theta_dot rad/s): a stream of its own, apart from the weights'. A trial
is truncated at 500 successful steps (not a failure, no punishment); its return, as Gymnasium
counts it, is its steps with the failing one: successful steps + 1 if it failed.

An episode can stop after any trial and resume from a checkpoint (core.checkpoint): it then
runs the seed's remaining trials, and its results equal those of the uninterrupted episode.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .checkpoint import Checkpoint, capture, check_resumable, restore
from .encoder import Encoder
from .params import CARTPOLE, Params
from .physics import CONTINUE, RAD_TO_DEG, CartPole, at_rest
from .agent import RLNAgent, SuccessCounter


def angle_grid(p: Params) -> np.ndarray:
    """The initial angles (deg): -span + 2 span k / (n - 1), k = 0..n-1."""
    k = np.arange(p.n_angles)
    return -p.angle_span_deg + 2 * p.angle_span_deg * k / (p.n_angles - 1)


def check_seed(seed) -> None:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")


def seed_setup(seed: int, p: Params) -> tuple[np.ndarray, np.ndarray]:
    """(initial weights, initial angles of every trial) for a seed."""
    check_seed(seed)
    rng = np.random.default_rng(seed)
    weights = p.w_base + rng.uniform(0, p.w_range, size=(p.n_actions, p.n_segments, p.n_inputs))
    grid = angle_grid(p)
    rounds = -(-p.trials // p.n_angles)
    angles = np.concatenate([grid[rng.permutation(p.n_angles)] for _ in range(rounds)])
    return weights, angles[:p.trials]


# The gymnasium protocol's starts of seed s: CartPole-v1's after reset(seed=STARTS_SEED + s).
STARTS_SEED = 2**32
RESET_BOUND = 0.05   # CartPole-v1's reset draws every variable uniform in +-this


def trial_starts(seed: int, p: Params, angles: np.ndarray | None = None) -> tuple[np.ndarray, bool]:
    """Every trial's start (x, x_dot, theta, theta_dot), (trials, 4), and whether its angles are
    in radians: the paper's protocol (or `angles`, deg): at rest at the seed's initial angles;
    gymnasium's: the successive starts of CartPole-v1's reset() (module docstring)."""
    if angles is None and p.protocol == "gymnasium":
        check_seed(seed)
        return gymnasium_starts(seed, p.trials), True
    angles = seed_setup(seed, p)[1] if angles is None else np.asarray(angles, dtype=np.float64)
    return np.array([at_rest(a) for a in angles], dtype=np.float64).reshape(-1, 4), False


def gymnasium_starts(seed: int, count: int) -> np.ndarray:
    """The first `count` starts of CartPole-v1's protocol for the seed (radians)."""
    return np.random.default_rng(STARTS_SEED + seed).uniform(-RESET_BOUND, RESET_BOUND,
                                                             size=(count, 4))


def trial_start(seed: int, p: Params, trial: int, initial_angle_deg: float) -> tuple:
    """(start, whether in radians) of the seed's trial `trial`, as an environment node takes it
    from the trial's START: the paper's, at rest at its angle; gymnasium's, drawn from its
    seed."""
    if p.protocol == "paper":
        return at_rest(initial_angle_deg), False
    return gymnasium_starts(seed, trial + 1)[trial], True


def initial_angles(seed: int, p: Params) -> np.ndarray:
    """Each trial's first pole angle (deg) under the seed's protocol; 0 for every trial of
    another task (its reset draws its start)."""
    if p.task != CARTPOLE:
        return np.zeros(p.trials)
    starts, in_radians = trial_starts(seed, p)
    return np.array([first_angle(start, in_radians) for start in starts])


def reset_for_trial(env, seed: int, trial: int, start, start_in_radians: bool) -> tuple:
    """Put `env` at the start of the seed's trial `trial` (trial_starts); CartPole-v1's
    protocol's start is drawn by Gymnasium's own reset() where env is Gymnasium's
    (env.reset_as_gymnasium: the same numbers). Returns the state (deg)."""
    if start_in_radians and hasattr(env, "reset_as_gymnasium"):
        return env.reset_as_gymnasium(STARTS_SEED + seed, trial)
    return env.reset(start, start_in_radians)


def returns(steps: np.ndarray, end_status: np.ndarray) -> np.ndarray:
    """Each trial's return as Gymnasium counts it: its steps, the failing one included."""
    return np.asarray(steps) + (np.asarray(end_status) != CONTINUE)


@dataclass
class EpisodeResult:
    seed: int
    initial_angles: np.ndarray  # (trials,) deg: each trial's first pole angle
    steps: np.ndarray  # (trials,) successful steps
    end_status: np.ndarray  # (trials,) physics status that ended it (CONTINUE: reached the cap)
    final_weights: np.ndarray
    checkpoint: Checkpoint | None = None  # the state after the last trial: resume from it


def play_trial(agent: RLNAgent, counter: SuccessCounter, encoder: Encoder, observation,
               step: Callable[[int], tuple], max_steps: int, learn: bool = True,
               trial: int = 0) -> tuple[int, float, bool]:
    """Run trial `trial` of an episode of any task from `observation`, its first: every tick the
    agent acts on the encoded observation, `step(action)` returns (observation, reward,
    terminated, truncated) as Gymnasium's step does, the success counter turns the outcome into
    a reward kind and the agent learns it. The trial ends when the step terminated or truncated
    the episode, or after max_steps steps. Returns (steps taken, the rewards' sum, whether it
    terminated)."""
    agent.begin_trial(trial, learn)
    counter.begin_trial()
    steps, total = 0, 0.0
    while steps < max_steps:
        action, _ = agent.act(encoder.spikes(observation))
        observation, reward, terminated, truncated = step(action)
        total += reward
        kind = counter.outcome(terminated, reward)
        if learn:
            agent.learn(kind)
        steps += 1
        if terminated or truncated:
            return steps, total, bool(terminated)
    return steps, total, False


def run_trial(agent: RLNAgent, counter: SuccessCounter, env: CartPole, encoder: Encoder,
              p: Params, learn: bool = True, trace: Callable[[tuple], None] | None = None,
              trial: int = 0) -> tuple[int, int]:
    """Run trial `trial` of a cart-pole episode from the state env was reset to; returns
    (successful steps, end status). `trace` gets the state after each step."""
    status = CONTINUE

    def step(action: int) -> tuple:
        nonlocal status
        status = env.step(action)
        if trace is not None:
            trace(env.state)
        return env.state, 0.0, status != CONTINUE, False

    steps, _, failed = play_trial(agent, counter, encoder, env.state, step, p.max_steps, learn,
                                  trial)
    return steps - failed, status


def start_episode(seed: int, p: Params, weights: np.ndarray | None = None,
                  resume: Checkpoint | None = None) -> tuple[RLNAgent, SuccessCounter, int]:
    """(agent, success counter, first trial) of an episode: new from the seed's weights or
    `weights`, or continuing the checkpoint `resume` (which must fit seed and p)."""
    if resume is None:
        weights = seed_setup(seed, p)[0] if weights is None else weights
        return RLNAgent(p, weights, seed=seed), SuccessCounter(p), 0
    if weights is not None:
        raise ValueError("weights and resume exclude each other: a checkpoint has its weights")
    check_resumable(resume, p, seed)
    return *restore(resume), resume.next_trial


def run_episode(seed: int, p: Params, weights: np.ndarray | None = None, learn: bool = True,
                angles: np.ndarray | None = None,
                env_factory: Callable[[Params], CartPole] = CartPole,
                resume: Checkpoint | None = None) -> EpisodeResult:
    """One episode with the seed protocol; `weights`/`angles` override the seed's own (`angles`:
    the paper's starts at these angles, deg); `env_factory(p)` makes the environment (e.g.
    tasks.cartpole.gymnasium_cartpole.GymCartPole); `resume` continues a checkpoint with the
    seed's remaining trials (up to p.trials)."""
    agent, counter, first_trial = start_episode(seed, p, weights, resume)
    starts, in_radians = trial_starts(seed, p, angles)
    if angles is None:
        starts = starts[first_trial:]
    env, encoder = env_factory(p), Encoder.from_params(p)
    steps = np.zeros(len(starts), dtype=np.int64)
    status = np.zeros(len(starts), dtype=np.int64)
    initial_angles = np.zeros(len(starts), dtype=np.float64)
    for trial, start in enumerate(starts):
        reset_for_trial(env, seed, first_trial + trial, start, in_radians)
        steps[trial], status[trial] = run_trial(agent, counter, env, encoder, p, learn,
                                                trial=first_trial + trial)
        initial_angles[trial] = first_angle(start, in_radians)
    return EpisodeResult(seed, initial_angles, steps, status, agent.weights.copy(),
                         capture(agent, counter, seed, first_trial + len(starts)))


def first_angle(start, in_radians: bool) -> float:
    """A start's pole angle in degrees (math.degrees' factor)."""
    return float(start[2]) * RAD_TO_DEG if in_radians else float(start[2])


def evaluate_weights(weights: np.ndarray, p: Params) -> EpisodeResult:
    """Fixed weights (no learning), one trial per grid angle: the paper's Figures 8 and 13."""
    return run_episode(0, p, weights=weights, learn=False, angles=angle_grid(p))
