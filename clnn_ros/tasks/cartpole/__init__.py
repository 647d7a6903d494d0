"""The paper's cart-pole as an environment node runs it: one of its simulators (the core's
physics as the parameters say, Gymnasium's CartPole-v1 itself, or a MuJoCo plant with its
constants), the trial's start from the seed protocol, and its task with its limits as bounds
and its two ways to fail as named terminations."""

from __future__ import annotations

from ...core.episode import reset_for_trial, trial_start
from ...core.params import ParamError, Params
from ...core.physics import CONTINUE, CartPole
from ...core.task import cartpole_task

# Its Observation.termination names (1 + index): the physics status that ended the trial
TERMINATIONS = ("pole_angle", "cart_position")


def simulator(name: str, params: Params):
    """(the cart-pole, its pole's half-length and track limit in m, for a drawing). Those that
    step their own tau import their engine only when chosen."""
    if name == "gymnasium":
        from .gymnasium_cartpole import GymCartPole
        cartpole, engine = GymCartPole(), "gymnasium"
        limits = cartpole.env.length, cartpole.env.x_threshold
    elif name == "mujoco":
        from .mujoco_cartpole import MujocoCartPole
        cartpole, engine = MujocoCartPole(), "MuJoCo"
        limits = cartpole.pole_length, cartpole.track_limit_m
    else:
        return CartPole(params), params.pole_length, params.track_limit_m
    if abs(cartpole.tau - params.tau) > 1e-12:
        raise ParamError(f"tau must be {engine}'s {cartpole.tau} s (one tick = one {engine} "
                         f"step), got {params.tau}")
    return (cartpole, *limits)


class CartPoleEnvironment:
    """The cart-pole with Gymnasium's two calls, its start the seed protocol's (the paper's
    angle of the trial's START, or CartPole-v1's draw): start() -> values, step(action) ->
    (values, reward, terminated, truncated, termination). Its values are the core's state (m,
    m/s, deg, deg/s); its reward 0 (the paper counts steps); it never truncates itself (the
    environment node truncates at max_steps)."""

    def __init__(self, params: Params, simulator_name: str):
        self.params, self.task = params, cartpole_task(params)
        self.termination_reasons = TERMINATIONS
        self.cartpole, self.pole_half_length_m, self.track_limit_m = simulator(simulator_name,
                                                                              params)

    def start(self, seed: int, trial: int, initial_angle_deg: float) -> tuple:
        return reset_for_trial(self.cartpole, seed, trial,
                               *trial_start(seed, self.params, trial, initial_angle_deg))

    def step(self, action: int) -> tuple:
        status = self.cartpole.step(action)  # action 1: +F
        return self.cartpole.state, 0.0, status != CONTINUE, False, status
