"""Named sets of parameter values ("presets"): a starting point that a command's own flags and
options override (`clnn-reproduce learn --preset NAME`, `sweep --preset`, `clnn-run --preset`;
`clnn-reproduce presets` lists them).

Each value is text, as params_from_strings takes it from the command line. A preset is for one
task: the paper's cart-pole and its variants where it names none, else the task its `task`
value names (`learn --task gymnasium:Acrobot-v1 --preset acrobot_v1`, `clnn-run --env
gymnasium:Acrobot-v1 --preset acrobot_v1`).
"""

from __future__ import annotations

from dataclasses import dataclass

from .physics import GYM_PHYSICS
from .params import CARTPOLE, ParamError


@dataclass(frozen=True)
class Preset:
    description: str
    values: dict[str, str]  # Params field -> text value


# Chosen on the selection seeds 128-191 and reported on 0-127 (docs/LEARNING.md, made by
# `clnn-reproduce goals`, records every candidate tried, the failures too).
PRESETS = {
    "gymnasium": Preset(
        "Gymnasium CartPole-v1's physics in the core's own simulator; pole angle and angular "
        "velocity encoded (edges +-1 deg/s), 36 segments per neuron, punishment twice Table 2's",
        {**{name: str(value) for name, value in GYM_PHYSICS.items()},
         "state_vars": "pole_angle,pole_angular_velocity",
         "angular_velocity_edges_deg_per_s": "-1,1", "segments": "36",
         "punish": "0.015625"}),
    # Chosen on the selection seeds 128-255 by a random and then a local search (docs/VERSUS.md)
    "cartpole_v1": Preset(
        "CartPole-v1's own protocol and physics (Gymnasium's step itself: random starts, "
        "truncated at 500 steps); pole angle (one edge, 0 deg), angular velocity (+-10 deg/s) "
        "and cart velocity (+-0.2 m/s) encoded, 9 segments per neuron, a reward every 128 "
        "steps, punishment window 1024 and 8x Table 2's punishment, rho_plus 4x, rho_minus 1/256",
        {**{name: str(value) for name, value in GYM_PHYSICS.items()}, "physics": "gymnasium",
         "protocol": "gymnasium", "max_steps": "500",
         "state_vars": "pole_angle,pole_angular_velocity,cart_velocity",
         "angle_edges_deg": "0", "angular_velocity_edges_deg_per_s": "-10,10",
         "velocity_edge": "0.2", "segments": "9", "sigma": "128", "omega": "1024",
         "punish": "0.0625", "rho_plus": "0.03125", "rho_minus": "0.00390625"}),
    "escape": Preset(
        "the paper's physics and encoding; out of its local optima with 12 segments per neuron, "
        "twice Table 2's punishment and no reward backoff (rho_minus 0)",
        {"segments": "12", "punish": "0.015625", "rho_minus": "0"}),
    # Chosen on the selection seeds 128-255 by scripts/task_search.py (docs/TASKS.md)
    "acrobot_v1": Preset(
        "Gymnasium's Acrobot-v1: the first link's angular velocity alone encoded (one edge, "
        "0 rad/s: two inputs), a punishment every 100 steps without reaching the line, a reward "
        "on reaching it for the 128 steps before",
        {"task": "gymnasium:Acrobot-v1", "state_vars": "theta1_dot",
         "variable_edges": "theta1_dot:0", "omega": "100", "sigma": "128"}),
    "mountain_car_v0": Preset(
        "Gymnasium's MountainCar-v0, the search's best, which does NOT solve it (6 of 128 "
        "selection seeds): position (-0.9, -0.5, -0.2 m) and velocity (-0.005, 0, 0.005 m/s) "
        "encoded, a punishment every 120 steps without the flag, a reward on reaching it for "
        "the 128 steps before, rho_minus 1/256",
        {"task": "gymnasium:MountainCar-v0", "state_vars": "position,velocity",
         "variable_edges": "position:-0.9,-0.5,-0.2;velocity:-0.005,0,0.005", "omega": "120",
         "sigma": "128", "rho_minus": "0.00390625"}),
    "inverted_pendulum_v5": Preset(
        "Gymnasium's InvertedPendulum-v5 with forces -1 and +1, the search's best, which does NOT "
        "solve it: hinge angle (one edge, 0 rad), its angular velocity (+-0.1745 rad/s) and the "
        "slider's velocity (+-0.2 m/s) encoded, 16 segments per neuron, a reward every 64 "
        "steps, punishment window 128 and 8x Table 2's punishment, rho_plus 4x, rho_minus 1/256",
        {"task": "gymnasium:InvertedPendulum-v5",
         "state_vars": "hinge_angle,hinge_angular_velocity,slider_velocity",
         "variable_edges": "slider_position:-0.5,0.5;hinge_angle:0;slider_velocity:-0.2,0.2;"
                           "hinge_angular_velocity:-0.17453292519943295,0.17453292519943295",
         "segments": "16", "omega": "128", "sigma": "64", "punish": "0.0625",
         "rho_plus": "0.03125", "rho_minus": "0.00390625"}),
}


def preset_values(name: str) -> dict[str, str]:
    """A copy of the preset's values; ParamError with one line for an unknown name."""
    if name not in PRESETS:
        raise ParamError(f"unknown preset {name!r}; known: {', '.join(PRESETS)}")
    return dict(PRESETS[name].values)


def preset_task(name: str) -> str:
    """The task a preset is for (ParamError for an unknown name)."""
    return preset_values(name).get("task", CARTPOLE)


def check_preset_task(name: str, task_name: str) -> None:
    """ParamError with one line where the preset is for a task other than `task_name`."""
    own = preset_task(name)
    if own != task_name:
        where = "the cart-pole" if own == CARTPOLE else f"--task {own} (clnn-run --env {own})"
        other = "the cart-pole" if task_name == CARTPOLE else task_name
        raise ParamError(f"preset {name} is for {where}, not {other}")


def overlay_values(values: dict, changes: dict) -> dict:
    """values with changes on top. nsv and state_vars say the same thing, so a change of one
    alone drops the other (as Params.replace does): a preset's state_vars give way to a later
    --nsv, and the other way round; both in one change must agree."""
    kept = dict(values)
    if "state_vars" in changes and "nsv" not in changes:
        kept.pop("nsv", None)
    if "nsv" in changes and "state_vars" not in changes:
        kept.pop("state_vars", None)
    return {**kept, **changes}
