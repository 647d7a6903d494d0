"""Gymnasium's CartPole-v1 physics behind the core's environment interface (CartPole's reset,
step and state), so that the core, the batch-engine comparison and the gymnasium environment
node (clnn_ros/nodes/environment.py, simulator gymnasium) all drive the very same simulator.

Gymnasium's own constants apply (core.physics.GYM_PHYSICS); the model's Params do not
change them. Gymnasium keeps the state in radians (float64); the state seen by the encoder and
published on /env/observation is in degrees: math.degrees(rad).

    env = GymCartPole(); env.reset(at_rest(0.5)); status = env.step(1)
    x, x_dot, th_deg, thd_deg = env.state
"""

from __future__ import annotations

import math

import numpy as np

from ...core.physics import (CONTINUE, FAIL_ANGLE, FAIL_POSITION, GYM_PHYSICS,
                             start_in_units)


class GymCartPole:
    """Gymnasium's CartPole-v1 with the core's interface: reset(start), step(0|1) -> status,
    state = (x m, x_dot m/s, theta deg, theta_dot deg/s)."""

    def __init__(self, params=None):  # params accepted (and unused) for CartPole's signature
        import gymnasium  # imported here: the rest of the project does not need it

        # unwrapped: no TimeLimit, the trial's cap is max_steps
        self.env = gymnasium.make("CartPole-v1").unwrapped
        self.tau = self.env.tau
        self.state = (0.0, 0.0, 0.0, 0.0)
        self._next_draw = None  # (reset seed, trial) whose start the next reset() draws

    def reset(self, start, start_in_radians: bool = False) -> tuple:
        """Trial start at (x, x_dot, theta, theta_dot), angles in degrees or radians (set
        directly: gymnasium's reset() draws a start of its own)."""
        self.env.state = np.array(start_in_units(start, start_in_radians, True), dtype=np.float64)
        self.env.steps_beyond_terminated = None
        self._read_state()
        return self.state

    def reset_as_gymnasium(self, reset_seed: int, trial: int) -> tuple:
        """Trial `trial`'s start under CartPole-v1's protocol, drawn by gymnasium's own reset():
        reset(seed=reset_seed) for trial 0, one reset() more for each later trial (a resumed
        episode replays the draws of the trials before it)."""
        if (reset_seed, trial) == self._next_draw:
            self.env.reset()
        else:  # a new stream, or a resumed episode
            self.env.reset(seed=reset_seed)
            for _ in range(trial):
                self.env.reset()
        self._next_draw = (reset_seed, trial + 1)
        self._read_state()
        return self.state

    def step(self, action: int) -> int:
        """Action 0 pushes with -10 N, 1 with +10 N (gymnasium's own step); the status says
        which limit a terminated step crossed (the angle is checked first, as in the core)."""
        _, _, terminated, _, _ = self.env.step(int(action))
        self._read_state()
        if not terminated:
            return CONTINUE
        theta = self.env.state[2]
        return FAIL_ANGLE if abs(theta) > self.env.theta_threshold_radians else FAIL_POSITION

    def _read_state(self) -> None:
        x, x_dot, theta, theta_dot = (float(v) for v in self.env.state)
        self.state = (x, x_dot, math.degrees(theta), math.degrees(theta_dot))
