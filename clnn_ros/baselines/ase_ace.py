"""The ASE/ACE of Barto, Sutton & Anderson (1983) on the 162 BOXES, played on CartPole-v1.

A. G. Barto, R. S. Sutton, C. W. Anderson, "Neuronlike adaptive elements that can solve difficult
learning control problems", IEEE Trans. Systems, Man, and Cybernetics SMC-13(5):834-846, 1983.
The associative search element (ASE, the actor) and the adaptive critic element (ACE, the critic)
both read the decoder's one-hot box vector x(t), so each of their sums over inputs is the weight
of one box. The elements run in synchronous discrete time, as the paper's equations are written:
y(t) and p(t) come from the weights w(t) and v(t); r_hat(t) then takes the weights to t + 1.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Callable

import gymnasium
import numpy as np

from ..core.solving import solved_episode

# The paper's thresholds inside the failure limits: 3 x 3 x 6 x 3 = 162 boxes.
X_EDGES_M = (-0.8, 0.8)
X_DOT_EDGES_M_PER_S = (-0.5, 0.5)
THETA_EDGES_DEG = (-6.0, -1.0, 0.0, 1.0, 6.0)
THETA_DOT_EDGES_DEG_PER_S = (-50.0, 50.0)
N_BOXES = 162
# Gymnasium's failure limits (its own expressions), rounded to float32 like its observations:
# rounding is monotone, so a state Gymnasium did not terminate never decodes as the failure box.
X_LIMIT_M = float(np.float32(2.4))
THETA_LIMIT_RAD = float(np.float32(12 * 2 * math.pi / 360))



def boxes(observation) -> int | None:
    """The box index (0..161) of a Gymnasium observation (x, x_dot, theta [rad], theta_dot
    [rad/s]); None beyond the track or angle limit. Each interval is closed below: a value on a
    threshold belongs to the box above it (as in Sutton and Anderson's pole.c)."""
    x, x_dot, theta, theta_dot = (float(value) for value in observation)
    if abs(x) > X_LIMIT_M or abs(theta) > THETA_LIMIT_RAD:
        return None
    index = 0
    for value, edges in ((x, X_EDGES_M), (x_dot, X_DOT_EDGES_M_PER_S),
                         (math.degrees(theta), THETA_EDGES_DEG),
                         (math.degrees(theta_dot), THETA_DOT_EDGES_DEG_PER_S)):
        index = index * (len(edges) + 1) + bisect.bisect_right(edges, value)
    return index


@dataclass(frozen=True)
class AseAceParams:
    """The paper's values for its ASE/ACE pole-balancing runs (the same in pole.c).

    alpha: ASE learning rate in w(t+1) = w(t) + alpha r_hat(t) e(t).
    beta: ACE learning rate in v(t+1) = v(t) + beta r_hat(t) x_bar(t).
    delta: decay of the ASE eligibility, e(t+1) = delta e(t) + (1 - delta) y(t) x(t).
    lambda_: decay of the ACE input trace, x_bar(t+1) = lambda x_bar(t) + (1 - lambda) x(t).
    gamma: discount in r_hat(t) = r(t) + gamma p(t) - p(t-1).
    sigma: standard deviation of the ASE's zero-mean Gaussian noise(t) (pole.c instead draws the
        action from a logistic function of w; the paper's threshold unit with noise is used here).
    """

    alpha: float = 1000.0
    beta: float = 0.5
    delta: float = 0.9
    lambda_: float = 0.8
    gamma: float = 0.95
    sigma: float = 0.01


class AseAce:
    """One ASE and one ACE on the 162 boxes, all weights and traces starting at zero.

    Per step: act(box of x(t)), step the environment, learn(box of x(t+1), failed, truncated).
    """

    def __init__(self, params: AseAceParams, rng: np.random.Generator):
        self.params = params
        self._rng = rng
        self.action_weights = np.zeros(N_BOXES)  # w, the ASE's
        self.critic_weights = np.zeros(N_BOXES)  # v, the ACE's
        self.eligibility = np.zeros(N_BOXES)  # e, the ASE's
        self.input_trace = np.zeros(N_BOXES)  # x_bar, the ACE's
        self._box = 0  # x(t), as an index
        self._output = 0.0  # y(t), +1 or -1
        self._prediction = 0.0  # p(t)
        # r_hat(t), computed when x(t) arrived; it moves the weights only after y(t) was chosen
        # from w(t), so the next learn() applies it first.
        self._internal_reinforcement = 0.0

    def act(self, box: int) -> int:
        """y(t) = f(w(t) x(t) + noise(t)) with f(s) = +1 if s >= 0 else -1, as Gymnasium's action
        (1 = push right = +F for y = +1, 0 = push left); the ACE's p(t) = v(t) x(t) goes with it."""
        noise = self._rng.normal(0.0, self.params.sigma)
        self._box = box
        self._output = 1.0 if self.action_weights[box] + noise >= 0.0 else -1.0
        self._prediction = float(self.critic_weights[box])
        return int(self._output > 0.0)

    def frozen_action(self, observation) -> int:
        """The learned action for a Gymnasium observation without the exploring noise, y =
        f(w x): the policy as it is played frozen."""
        return int(self.action_weights[boxes(observation)] >= 0.0)

    def learn(self, next_box: int | None, failed: bool, truncated: bool) -> None:
        """Ends time t (weights to t+1, traces take in x(t), y(t)) and computes r_hat(t+1) from
        the box of x(t+1): r = -1 and p = 0 on failure. At the episode's end (failure or
        truncation) r_hat(t+1) is applied at once and the traces are cleared for the next one."""
        params = self.params
        self._apply_internal_reinforcement()
        self.eligibility *= params.delta
        self.eligibility[self._box] += (1.0 - params.delta) * self._output
        self.input_trace *= params.lambda_
        self.input_trace[self._box] += 1.0 - params.lambda_
        # Truncation is not a failure: r = 0 and the truncated state's own prediction is
        # bootstrapped, as the time-limit-aware treatment does (Pardo et al. 2018; Gymnasium's
        # terminated/truncated split, SB3's handle_timeout_termination). Only failures are -1.
        reinforcement = -1.0 if failed else 0.0
        next_prediction = 0.0 if failed else float(self.critic_weights[next_box])
        self._internal_reinforcement = (reinforcement + params.gamma * next_prediction
                                        - self._prediction)
        if failed or truncated:
            # No y(t+1) follows in this episode, so r_hat(t+1) reaches the weights now.
            self._apply_internal_reinforcement()
            self.eligibility[:] = 0.0
            self.input_trace[:] = 0.0

    def _apply_internal_reinforcement(self) -> None:
        r_hat = self._internal_reinforcement
        self.action_weights += self.params.alpha * r_hat * self.eligibility
        self.critic_weights += self.params.beta * r_hat * self.input_trace
        self._internal_reinforcement = 0.0


def new_agent(seed: int) -> AseAce:
    """The seed's ASE/ACE: the paper's values, its noise from a spawned child of
    SeedSequence(seed) (train's docstring says why)."""
    return AseAce(AseAceParams(), np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0]))


def train(seed: int, max_episodes: int,
          env_factory: Callable[[], gymnasium.Env] | None = None,
          agent: AseAce | None = None) -> np.ndarray:
    """The returns (steps, the failing one included) of up to max_episodes episodes of one
    ASE/ACE, stopping once it has solved CartPole-v1 (core.solving). Deterministic for a seed.

    Seeding as CleanRL and Stable-Baselines3 do it: the first reset is env.reset(seed=seed), the
    later ones env.reset() continue the env's own stream. The agent's noise comes from a spawned
    child of SeedSequence(seed), not from default_rng(seed): Gymnasium seeds the env with
    PCG64(SeedSequence(seed)), the very stream default_rng(seed) would give the agent.
    """
    env = env_factory() if env_factory is not None else gymnasium.make("CartPole-v1")
    agent = agent if agent is not None else new_agent(seed)  # given: the caller keeps it
    returns: list[int] = []
    try:
        for episode in range(max_episodes):
            observation, _ = env.reset(seed=seed if episode == 0 else None)
            box = boxes(observation)
            steps = 0
            terminated = truncated = False
            while not (terminated or truncated):
                observation, _, terminated, truncated, _ = env.step(agent.act(box))
                steps += 1
                box = None if terminated else boxes(observation)
                agent.learn(box, failed=terminated, truncated=truncated)
            returns.append(steps)
            if solved_episode(returns) is not None:
                break
    finally:
        env.close()
    return np.array(returns)
