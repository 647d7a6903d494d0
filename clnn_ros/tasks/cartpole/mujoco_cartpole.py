"""A cart-pole simulated by MuJoCo behind the core's environment interface (CartPole's reset, step
and state), so that the core (`run_episode(seed, p, env_factory=MujocoCartPole)`) and the MuJoCo
environment node (clnn_ros/nodes/environment.py, simulator mujoco) drive the very same plant.

The plant is the MJCF model below, built with Gymnasium CartPole-v1's constants (GYM_PHYSICS):
a 1.0 kg cart on a frictionless slide joint along x; on it a hinge about y (no damping, no
friction) carrying a 0.1 kg pole whose centre of mass lies 0.5 m above the hinge, with the
inertia of a uniform rod 1.0 m long about its centre, m (2l)^2 / 12 (about the hinge that is
(4/3) m l^2, the 4/3 of Gymnasium's equations); gravity 9.8 m/s^2; a motor on the slide joint
(gear 1, ctrlrange +-10 N) pushes the cart with -10 N (action 0) or +10 N (action 1). Contacts are
off: nothing collides, as in the equations. The hinge turns about +y, so a positive angle leans
the pole toward +x, and +F pushes the cart toward +x: the core's conventions (core/physics.py).

One step is one mj_step of MuJoCo's default "Euler" integrator with timestep 0.02 s: that is
semi-implicit Euler (velocities first, positions from the new velocities), so the plant is the
core's `correct` physics with integrator `semi_implicit`, computed by MuJoCo's rigid-body
algorithms from the model instead of by the closed-form equations; the two agree to rounding
(tests/test_mujoco_env.py, docs/MUJOCO.md). Substeps (e.g. 10 x 0.002 s, or RK4) would make a
plant closer to continuous time but no longer the discrete-time model that the core, the batch
engine and the paper step at 0.02 s: it could not be checked against them step by step, and a
learning result on it would mix the change of plant with a change of integration.

The state is qpos and qvel, the pole's converted to degrees: (x m, x_dot m/s, theta deg,
theta_dot deg/s). After each step the angle limit (12 deg) is checked first, then the track
(2.4 m), as in the core. The model's Params do not change the plant.

    env = MujocoCartPole(); env.reset(at_rest(0.5)); status = env.step(1)
    x, x_dot, theta_deg, theta_dot_deg = env.state
"""

from __future__ import annotations

import math

from ...core.physics import CONTINUE, FAIL_ANGLE, FAIL_POSITION, GYM_PHYSICS, start_in_units

# The pole's inertia about its own axis: irrelevant to a hinge about y, but MuJoCo needs every
# principal moment positive; a thin rod's is tiny.
POLE_AXIAL_INERTIA = 1e-6
# The cart only slides: its rotational inertia never enters the dynamics (MuJoCo needs one).
CART_INERTIA = 0.01


def cartpole_mjcf(cart_mass: float, pole_mass: float, pole_length: float, gravity: float,
                  force: float, tau: float) -> str:
    """The MJCF model of a cart-pole with these constants (pole_length: the half-length l)."""
    rod_inertia = pole_mass * (2 * pole_length) ** 2 / 12  # uniform rod about its centre
    return f"""
<mujoco model="cartpole">
  <option timestep="{tau!r}" integrator="Euler" gravity="0 0 {-gravity!r}">
    <flag contact="disable"/>
  </option>
  <worldbody>
    <body name="cart">
      <joint name="slide" type="slide" axis="1 0 0"/>
      <inertial pos="0 0 0" mass="{cart_mass!r}"
                diaginertia="{CART_INERTIA!r} {CART_INERTIA!r} {CART_INERTIA!r}"/>
      <body name="pole">
        <joint name="hinge" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 {pole_length!r}" mass="{pole_mass!r}"
                  diaginertia="{rod_inertia!r} {rod_inertia!r} {POLE_AXIAL_INERTIA!r}"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="push" joint="slide" gear="1" ctrllimited="true"
           ctrlrange="{-force!r} {force!r}"/>
  </actuator>
</mujoco>
"""


MJCF = cartpole_mjcf(*(GYM_PHYSICS[name] for name in
                       ("cart_mass", "pole_mass", "pole_length", "gravity", "force", "tau")))


class MujocoCartPole:
    """MuJoCo's cart-pole with the core's interface: reset(start), step(0|1) -> status,
    state = (x m, x_dot m/s, theta deg, theta_dot deg/s)."""

    def __init__(self, params=None):  # params accepted (and unused) for CartPole's signature
        import mujoco  # imported here: the rest of the core does not need it

        self._mujoco = mujoco
        self.model = mujoco.MjModel.from_xml_string(MJCF)
        self.data = mujoco.MjData(self.model)
        self.tau = float(self.model.opt.timestep)
        self.force = GYM_PHYSICS["force"]
        self.angle_limit_deg = GYM_PHYSICS["angle_limit_deg"]
        self.track_limit_m = GYM_PHYSICS["track_limit_m"]
        self.pole_length = GYM_PHYSICS["pole_length"]
        self.state = (0.0, 0.0, 0.0, 0.0)

    def reset(self, start, start_in_radians: bool = False) -> tuple:
        """Trial start at (x, x_dot, theta, theta_dot), angles in degrees or radians (set
        directly)."""
        self._mujoco.mj_resetData(self.model, self.data)
        x, x_dot, theta, theta_dot = start_in_units(start, start_in_radians, True)
        self.data.qpos[:] = (x, theta)
        self.data.qvel[:] = (x_dot, theta_dot)
        self._read_state()
        return self.state

    def step(self, action: int) -> int:
        """Action 0 pushes with -10 N, 1 with +10 N, for one mj_step; the status says which
        limit the step crossed (the angle is checked first, as in the core)."""
        self.data.ctrl[0] = self.force if action == 1 else -self.force
        self._mujoco.mj_step(self.model, self.data)
        self._read_state()
        x, _, theta_deg, _ = self.state
        if abs(theta_deg) > self.angle_limit_deg:
            return FAIL_ANGLE
        return FAIL_POSITION if abs(x) > self.track_limit_m else CONTINUE

    def _read_state(self) -> None:
        x, theta = (float(v) for v in self.data.qpos)
        x_dot, theta_dot = (float(v) for v in self.data.qvel)
        self.state = (x, x_dot, math.degrees(theta), math.degrees(theta_dot))
