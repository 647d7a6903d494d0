"""The environment the project's environment node runs for a run's task: the cart-pole (one of
its simulators) or any Gymnasium task. Another task (a robot's) runs in a node of its own
(docs/ENV_CONTRACT.md)."""

from __future__ import annotations

from ..core.params import CARTPOLE, ParamError, Params
from .cartpole import CartPoleEnvironment
from .gymnasium_task import PREFIX, GymnasiumTaskEnvironment


def environment_for(params: Params, simulator: str, actions: str):
    """The environment of params.task; ParamError with one line for a task it does not run."""
    if params.task == CARTPOLE:
        if actions:
            raise ParamError(f"actions ({actions!r}) declares a Gymnasium task's values; the "
                             f"cart-pole's are -F and +F")
        return CartPoleEnvironment(params, simulator)
    if params.task.startswith(PREFIX):
        return GymnasiumTaskEnvironment(params, actions)
    raise ParamError(f"the project's environment node runs the cart-pole and Gymnasium's tasks "
                     f"({PREFIX}ID), not {params.task!r}: run your own node (--env-node, "
                     f"docs/ENV_CONTRACT.md)")
