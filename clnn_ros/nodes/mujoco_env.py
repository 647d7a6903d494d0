"""MuJoCo environment node: a cart-pole simulated by MuJoCo behind the environment contract
(docs/ENV_CONTRACT.md), a drop-in for clnn_ros.nodes.environment.

    python -m clnn_ros.run_all --env mujoco
    python -m clnn_ros.nodes.mujoco_env --ros-args --params-file params.yaml

It keeps the project environment node's protocol (ticks, START/action handling, refusals,
readiness, exit on EPISODE_END) and swaps only the simulator: the MJCF cart-pole of
clnn_ros.core.mujoco_physics (Gymnasium CartPole-v1's constants, one mj_step of 0.02 s per
tick), whose joints are set directly at START (cart at rest at 0, pole at rest at the trial
manager's initial angle) and whose motor pushes with -10 N or +10 N. The plant's own masses,
length, force and limits (12 deg, 2.4 m) apply; the model parameters of the run (cart_mass,
physics, ...) do not change them. The hinge's radians become the message's degrees.
"""

from __future__ import annotations

from ..core.mujoco_physics import MujocoCartPole
from .environment import EnvironmentNode
from .common import node_main


class MujocoEnvironmentNode(EnvironmentNode):
    def __init__(self, **options):
        super().__init__(**options)
        cartpole = MujocoCartPole()
        self.use_simulator(cartpole, "MuJoCo", cartpole.pole_length, cartpole.track_limit_m)


def main() -> None:
    raise SystemExit(node_main(MujocoEnvironmentNode))


if __name__ == "__main__":
    main()
