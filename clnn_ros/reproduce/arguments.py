"""The model's flags of `learn` and `sweep` (one set for both), and the Params they make: a
preset's values, then the command's own flags and --options on top."""

from __future__ import annotations

import argparse

from ..core.params import (CARTPOLE, PROTOCOLS, STATE_NAMES, Params, params_from_strings,
                           protocol_defaults)
from ..core.presets import PRESETS, check_preset_task, overlay_values, preset_values
from .common import DEFAULT_SEEDS, LITERAL_EDGE, TRIALS

PRESET_HELP = ("a named set of parameter values (" + ", ".join(PRESETS) + "; the command "
               "'presets' lists them) that the other flags and --options override")
# Params fields the commands set with a flag of their own, not --option
OWN_FLAGS = {"nsv": "--nsv", "state_vars": "--state-vars", "trials": "--trials",
             "velocity_edge": "--velocity-edge", "physics": "--physics",
             "protocol": "--protocol"}
CARTPOLE_FLAGS = ("nsv", "velocity_edge", "physics", "protocol")  # the cart-pole's alone


def add_model_flags(parser: argparse.ArgumentParser, option_help: str) -> None:
    parser.add_argument("--nsv", type=int, choices=(1, 2, 3, 4),
                        help="state variables: 1 (angle, the default), 2 (and cart velocity), 3 "
                             "(and cart position), 4 (and pole angular velocity)")
    parser.add_argument("--state-vars", metavar="NAMES",
                        help="the encoded state variables instead, in input order, of: "
                             + ", ".join(STATE_NAMES) + " (or the --task's own)")
    parser.add_argument("--seeds", default=DEFAULT_SEEDS, help="seeds, e.g. 0-31, 0,3,5 or 0-3,7")
    parser.add_argument("--preset", metavar="NAME", help=PRESET_HELP)
    parser.add_argument("--trials", type=int, help=f"trials per episode (default {TRIALS})")
    parser.add_argument("--velocity-edge", type=str, default=None,
                        help=f"velocity edge in m/s (default: Table 1's {LITERAL_EDGE:g})")
    parser.add_argument("--physics", default=None,
                        help="paper (default), correct, integration_slip or gymnasium")
    parser.add_argument("--protocol", choices=PROTOCOLS, default=None,
                        help="paper (default: 32 start angles, the cart at rest) or gymnasium "
                             "(CartPole-v1's: random starts, truncated at 500 steps)")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help=option_help)


def given_values(args) -> dict[str, str]:
    """The Params values (text) that the command's own flags and --options give."""
    given = {name: str(getattr(args, name)) for name in OWN_FLAGS
             if getattr(args, name) is not None}
    for item in args.option:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"--option expects key=value, got {item!r}")
        if key in OWN_FLAGS:
            raise ValueError(f"set {key} with {OWN_FLAGS[key]}, not --option")
        given[key] = value.strip()
    return given


def learn_params(args) -> Params:
    """The preset's values (the command's default trials under them), then the command's own
    flags and --options on top."""
    values = {"trials": str(TRIALS)}
    if args.preset is not None:
        check_preset_task(args.preset, CARTPOLE)
        values = overlay_values(values, preset_values(args.preset))
    return params_from_strings(protocol_defaults(overlay_values(values, given_values(args))))


def add_task_flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--task", default=CARTPOLE, metavar="NAME",
                        help=f"{CARTPOLE} (the default: the paper's, with the batch engine), or "
                             "gymnasium:ID, any registered Gymnasium task with a Box observation "
                             "and Discrete actions, e.g. gymnasium:Acrobot-v1 (the core with "
                             "its rule compiled, its seeds in --workers processes, default one "
                             "per CPU)")
    parser.add_argument("--actions", metavar="V1,V2,...",
                        help="with --task gymnasium:ID of a Box action space: the values the "
                             "agent may apply, one RLN each, e.g. --actions=-3,3 (with '=': "
                             "argparse takes -3,3 alone for a flag)")


def task_values(args) -> dict[str, str]:
    """The Params values (text) of `learn` or `sweep --task` for a task other than the
    cart-pole: the task's preset, then the command's values; the flags for the cart-pole alone,
    and another task's preset, are refused in one line."""
    refused = [OWN_FLAGS[name] for name in CARTPOLE_FLAGS if getattr(args, name) is not None]
    refused += ["--ray"] if args.ray is not None else []
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be at least 1, got {args.workers}")
    if refused:
        raise ValueError(f"{refused[0]} is for the cart-pole, not --task {args.task}")
    values = {"trials": str(TRIALS)}
    if args.preset is not None:
        check_preset_task(args.preset, args.task)
        values.update(preset_values(args.preset))
    return {**values, **given_values(args)}
