"""Gymnasium environment node: gymnasium's CartPole-v1 physics behind the environment contract
(docs/ENV_CONTRACT.md), a drop-in for clnn_ros.nodes.environment.

    python -m clnn_ros.run_all --env gymnasium
    python -m clnn_ros.nodes.gymnasium_env --ros-args --params-file params.yaml

It keeps the project environment node's protocol (ticks, START/action handling, refusals,
readiness, exit on EPISODE_END) and swaps only the simulator: gymnasium.make("CartPole-v1")
.unwrapped, whose state is set directly at START (the trial manager's initial angle converted
to radians, cart at rest at 0) and stepped with action 0 (-10 N) or 1 (+10 N). Gymnasium's own
masses, length, force and limits apply (12 deg = 0.2095 rad, 2.4 m); the model parameters of
the run (cart_mass, physics, ...) do not change them. Radians become the message's degrees.
"""

from __future__ import annotations

from ..core.gym_physics import GymCartPole
from .environment import EnvironmentNode
from .common import node_main


class GymnasiumEnvironmentNode(EnvironmentNode):
    def __init__(self, **options):
        super().__init__(**options)
        cartpole = GymCartPole()
        self.use_simulator(cartpole, "gymnasium", cartpole.env.length, cartpole.env.x_threshold)


def main() -> None:
    raise SystemExit(node_main(GymnasiumEnvironmentNode))


if __name__ == "__main__":
    main()
