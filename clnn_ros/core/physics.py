"""Cart-pole dynamics of Smith (2024), section 1.2, after Nagendra et al. (2017).

Equations (F > 0 pushes toward +x; theta > 0 leans toward +x, so +F makes theta_acc < 0):

    theta_acc = ((M+m) g sin(th) - cos(th) (F + m l th_dot^2 sin(th))) / ((4/3)(M+m) l - m l cos^2(th))
    x_acc     = (F + m l (th_dot^2 sin(th) - theta_acc cos(th))) / (M+m)

with M = 0.711 kg, m = 0.209 kg, l = 0.326 m, g = 9.8 m/s^2, F = +-10 N, tau = 0.02 s. This is the
same model as Gymnasium's CartPole-v1 (Barto, Sutton & Anderson 1983; Florian 2007) with its own
masses and half-length. The state is kept as (x [m], x_dot [m/s], theta [deg], theta_dot [deg/s]).

Two physics modes:

* ``correct``: the equations above in consistent units; theta_acc (rad/s^2) is converted to
  deg/s^2 before it is added to theta_dot.
* ``paper`` (default): the units slip that reproduces the paper's numbers. theta_acc is computed in
  rad/s^2 but added to theta_dot in deg/s, so the pole's angular acceleration is too small by
  180/pi; the cart sees the same scaled acceleration, so the motion is self-consistent, just with
  a slow pole. Evidence: with it, no force lets the pole fall in ~275 steps and a constant force
  drives the cart off the track in exactly 32 steps, the paper's section 3.1 figures (correct
  physics gives ~35 steps for the first). See docs/REPRODUCTION.md.
* ``integration_slip``: the other reading of that slip, in the integration only: theta_acc in
  rad/s^2 is added to theta_dot in deg/s, but the cart equation sees the true theta_acc (rad/s^2).
  A constant force then drives the cart off the track in 29 steps, not the paper's 32.

* ``gymnasium``: Gymnasium's CartPole-v1 step itself (gymnasium/envs/classic_control/cartpole.py):
  its equations written as it writes them, float operation by float operation, with the state in
  radians as it keeps it, so that its results are Gymnasium's bit for bit (tests/test_protocol.py);
  the encoder sees that state in degrees (x * 180/pi, as math.degrees computes it). The same
  model as ``correct``, which computes it in another order and in degrees (equal up to rounding).

Integrators: ``semi_implicit`` Euler, velocities first (x_dot += tau x_acc; x += tau x_dot; ...),
the paper's default, or explicit ``euler`` (positions from the old velocities, as Gymnasium's
default). A trial fails when |theta| > angle limit or |x| > track limit after a step.

The step function is written in the subset of Python that numba compiles (``jitable``),
so the batch engine runs this very code.
"""

from __future__ import annotations

import math

from .jitable import jitable
from .params import Params

DEG = math.pi / 180.0  # radians per degree (math.radians' factor)
RAD_TO_DEG = 180.0 / math.pi  # degrees per radian (math.degrees' factor)
CONTINUE, FAIL_ANGLE, FAIL_POSITION = 0, 1, 2


def physics_constants(p: Params) -> tuple:
    """The numbers physics_step needs, as a flat tuple (numba passes tuples cheaply)."""
    # How theta_acc in rad/s^2 becomes deg/s^2 in the state: the paper's slip skips the 180/pi.
    angular_to_state = 180.0 / math.pi if p.physics == "correct" else 1.0
    # How that deg/s^2 becomes the rad/s^2 the cart equation sees: with integration_slip the cart
    # sees theta_acc itself.
    state_to_cart = 1.0 if p.physics == "integration_slip" else DEG
    return (p.cart_mass + p.pole_mass, p.pole_mass * p.pole_length, p.pole_length, p.gravity,
            p.tau, angular_to_state, state_to_cart, p.integrator == "semi_implicit",
            p.angle_limit_deg, p.track_limit_m, p.pole_mass,
            p.angle_limit_deg * 2 * math.pi / 360)  # gymnasium's limit in radians, as it has it


def state_in_radians(p: Params) -> bool | None:
    """True where the physics keeps its state in radians (gymnasium), None where in degrees: a
    type of its own, so that the compiled engine picks its step when it is compiled rather than
    on every tick (a branch there cost it a third of its speed)."""
    return True if p.physics == "gymnasium" else None


@jitable
def integrate(x, x_dot, theta, theta_dot, x_acc, theta_acc, tau, semi_implicit):
    """One step of the integrator (gymnasium's two, in its order): semi-implicit Euler moves
    the positions with the new velocities, explicit Euler with the old."""
    if semi_implicit:
        x_dot = x_dot + tau * x_acc
        x = x + tau * x_dot
        theta_dot = theta_dot + tau * theta_acc
        theta = theta + tau * theta_dot
    else:
        x = x + tau * x_dot
        x_dot = x_dot + tau * x_acc
        theta = theta + tau * theta_dot
        theta_dot = theta_dot + tau * theta_acc
    return x, x_dot, theta, theta_dot


@jitable
def cartpole_step(x, x_dot, theta_deg, theta_dot_deg, force, constants):
    """Advance one time step tau under `force` (N). Returns (x, x_dot, theta_deg, theta_dot_deg, status)
    with status CONTINUE, FAIL_ANGLE or FAIL_POSITION."""
    (total_mass, pole_mass_length, length, gravity, tau, angular_to_state, state_to_cart,
     semi_implicit, angle_limit_deg, track_limit_m) = constants[:10]
    theta = theta_deg * DEG
    theta_dot = theta_dot_deg * DEG
    sin_theta = math.sin(theta)
    cos_theta = math.cos(theta)
    theta_acc = ((total_mass * gravity * sin_theta
                  - cos_theta * (force + pole_mass_length * theta_dot * theta_dot * sin_theta))
                 / ((4.0 / 3.0) * total_mass * length - pole_mass_length * cos_theta * cos_theta))
    theta_acc_state = theta_acc * angular_to_state  # deg/s^2 as added to theta_dot_deg
    theta_acc_seen = theta_acc_state * state_to_cart  # what the cart equation sees, rad/s^2
    x_acc = (force + pole_mass_length * (theta_dot * theta_dot * sin_theta
                                         - theta_acc_seen * cos_theta)) / total_mass
    x, x_dot, theta_deg, theta_dot_deg = integrate(x, x_dot, theta_deg, theta_dot_deg, x_acc,
                                                   theta_acc_state, tau, semi_implicit)
    status = CONTINUE
    if abs(theta_deg) > angle_limit_deg:
        status = FAIL_ANGLE
    elif abs(x) > track_limit_m:
        status = FAIL_POSITION
    return x, x_dot, theta_deg, theta_dot_deg, status


@jitable
def gymnasium_step(x, x_dot, theta, theta_dot, force, constants):
    """Gymnasium CartPole-v1's step, the state in radians: its lines, in its order of float
    operations (np.square(v) is v * v). Returns (x, x_dot, theta, theta_dot, status); the angle
    limit is checked first, as in cartpole_step."""
    (total_mass, pole_mass_length, length, gravity, tau, _, _, semi_implicit, _, track_limit_m,
     pole_mass, angle_limit_rad) = constants
    costheta = math.cos(theta)
    sintheta = math.sin(theta)
    temp = (force + pole_mass_length * (theta_dot * theta_dot) * sintheta) / total_mass
    theta_acc = (gravity * sintheta - costheta * temp) / (
        length * (4.0 / 3.0 - pole_mass * (costheta * costheta) / total_mass))
    x_acc = temp - pole_mass_length * theta_acc * costheta / total_mass
    x, x_dot, theta, theta_dot = integrate(x, x_dot, theta, theta_dot, x_acc, theta_acc, tau,
                                           semi_implicit)
    status = CONTINUE
    if theta < -angle_limit_rad or theta > angle_limit_rad:
        status = FAIL_ANGLE
    elif x < -track_limit_m or x > track_limit_m:
        status = FAIL_POSITION
    return x, x_dot, theta, theta_dot, status


@jitable
def physics_step(x, x_dot, theta, theta_dot, force, constants, radians):
    """One step of the physics the constants name, in its own units (`radians`:
    state_in_radians): (x, x_dot, theta, theta_dot, status)."""
    if radians is None:
        return cartpole_step(x, x_dot, theta, theta_dot, force, constants)
    return gymnasium_step(x, x_dot, theta, theta_dot, force, constants)


@jitable
def in_degrees(x, x_dot, theta, theta_dot, radians):
    """The state as the encoder and the graph's messages have it (angles in degrees), from the
    physics' own state."""
    if radians is None:
        return x, x_dot, theta, theta_dot
    return x, x_dot, theta * RAD_TO_DEG, theta_dot * RAD_TO_DEG


def at_rest(initial_angle_deg: float) -> tuple:
    """The paper's trial start: cart centred and at rest, pole at rest at the angle (deg)."""
    return 0.0, 0.0, initial_angle_deg, 0.0


def start_in_units(start, start_in_radians: bool, radians: bool | None) -> tuple:
    """A trial's start (x, x_dot, theta, theta_dot) in a physics' own units (`radians`: as
    state_in_radians has them): the paper's protocol gives it in degrees, gymnasium's in
    radians; converted where the physics keeps the other unit (math.radians' and math.degrees'
    factors), else as it is, bit for bit."""
    x, x_dot, theta, theta_dot = (float(v) for v in start)
    if start_in_radians == bool(radians):
        return x, x_dot, theta, theta_dot
    factor = RAD_TO_DEG if start_in_radians else DEG
    return x, x_dot, theta * factor, theta_dot * factor


@jitable
def trial_start_state(x, x_dot, theta, theta_dot, released, constants, radians):
    """A trial's first state from its start (in the physics' units); with `released`
    (first_action="no_force") that state one step of F = 0 later (whether that step crossed a
    limit is told by the network's first step)."""
    if not released:
        return x, x_dot, theta, theta_dot
    x, x_dot, theta, theta_dot, _ = physics_step(x, x_dot, theta, theta_dot, 0.0, constants,
                                                 radians)
    return x, x_dot, theta, theta_dot


class CartPole:
    """The environment as an object: reset to a start, step with an action (0 = -F, 1 = +F).
    `state` is in degrees (the encoder's view); the physics keeps its own units."""

    def __init__(self, params: Params):
        self.params = params
        self._constants = physics_constants(params)
        self._radians = state_in_radians(params)
        self.state_in_own_units = (0.0, 0.0, 0.0, 0.0)
        self.state = (0.0, 0.0, 0.0, 0.0)

    def reset(self, start, start_in_radians: bool = False) -> tuple:
        """Trial start at (x, x_dot, theta, theta_dot), angles in degrees or radians (or one
        F = 0 step later: first_action="no_force"); the paper's: at_rest(angle)."""
        self.state_in_own_units = trial_start_state(
            *start_in_units(start, start_in_radians, self._radians),
            self.params.first_action == "no_force", self._constants, self._radians)
        self.state = in_degrees(*self.state_in_own_units, self._radians)
        return self.state

    def step(self, action: int) -> int:
        """Apply -F (action 0) or +F (action 1) for one tick; returns the failure status."""
        return self.step_force(self.params.force if action == 1 else -self.params.force)

    def step_force(self, force: float) -> int:
        """Apply any force (N) for one tick; returns the failure status."""
        *state, status = physics_step(*self.state_in_own_units, force, self._constants,
                                      self._radians)
        self.state_in_own_units = tuple(state)
        self.state = in_degrees(*state, self._radians)
        return status


# Gymnasium's CartPole-v1 as Params values (gymnasium/envs/classic_control/cartpole.py: its
# constants, true equations, explicit Euler, limits 12 deg and 2.4 m).
GYM_PHYSICS = dict(cart_mass=1.0, pole_mass=0.1, pole_length=0.5, gravity=9.8, force=10.0,
                   tau=0.02, physics="correct", integrator="euler", angle_limit_deg=12.0,
                   track_limit_m=2.4)


def gym_matched_params(p):
    """p with the core's own physics made the same model as gymnasium's CartPole-v1 (used to
    run the batch engine on gymnasium's physics)."""
    return p.replace(**GYM_PHYSICS)


def gym_exact_params(p):
    """p with the core's own physics made gymnasium's CartPole-v1 step itself, bit for bit
    (physics "gymnasium": its float operations, in radians), with its constants."""
    return p.replace(**{**GYM_PHYSICS, "physics": "gymnasium"})
