"""The rules of the environment contract (docs/ENV_CONTRACT.md) as clnn-check-env reports them,
and the rules of a published state. In the manner of Gymnasium's env_checker, each check_*
function checks one thing of what the node did and yields what is wrong with it (the text of a
FAIL line); nothing when the node keeps the rule. No ROS import: a rule reads message fields,
so RULES is read without rclpy."""

from __future__ import annotations

import math
from typing import Iterable, Iterator

from ..core.params import INTEGRATORS, PHYSICS, Params
from ..core.physics import (in_degrees, physics_constants, physics_step, start_in_units,
                            state_in_radians)
from ..graph.fields import (FAILURE_CART_POSITION, FAILURE_NONE, FAILURE_POLE_ANGLE,
                            FAILURE_REASONS, tick_nanoseconds)
from ..graph.names import ACTION, CLOCK, READY, STATE, TOPIC_TYPES, TRIAL_EVENT
from ..session.process_signals import EXIT_WITH_STDIN

RULES = {
    "starts": "the command starts a node that keeps running",
    "readiness": f"announces 'environment' on {READY} (TRANSIENT_LOCAL) once {STATE} has 3 "
                 f"subscribers",
    "interface": f"node 'environment' in the namespace it is given; subscribes {CLOCK}, "
                 f"{TRIAL_EVENT}, {ACTION}; publishes {STATE} (relative names, clnn_ros_msgs "
                 f"types, RELIABLE, VOLATILE)",
    "sim_time": "use_sim_time is true",
    "lockstep": "state(t) once, only after clock(t) and START(t) or action(t-1); tick t and "
                "the trial",
    "reset": "START resets: cart at 0 and at rest, pole at rest at initial_angle_deg, "
             "successful_steps 0, the START's trial",
    "successful_steps": "+1 per successful step, not for the failing one; a trial at max_steps "
                        "ends with force 0 and the next START is accepted",
    "failure": "failure: FAILURE_POLE_ANGLE beyond angle_limit_deg, FAILURE_CART_POSITION "
               "beyond track_limit_m, else FAILURE_NONE",
    "refusals": "refuses force_direction not in -1,0,1, an action or clock of another tick, "
                "START mid-trial, START outside the angle limit",
    "episode_end": "exits with status 0 on EPISODE_END",
    "stdin_eof": f"with {EXIT_WITH_STDIN}=1, exits when its stdin reaches end of file",
}
# Advisory unless --physics-from-run: a simulator of its own (gymnasium, friction, a robot)
# steps other physics than the run's and keeps the contract.
PHYSICS_RULE = {
    "physics": "the states follow the run's cart-pole: the equations of docs/ENV_CONTRACT.md "
               "with the physics parameters of the run's file",
}
STRICT_PHYSICS = "--physics-from-run"
NAME = "environment"  # the checked node's name
MAX_STEPS = 60  # the cap the checked node gets; the failing trial must fail before it
ANGLE_LIMIT_DEG, TRACK_LIMIT_M, TAU, FORCE_N = 12.0, 2.4, 0.02, 10.0  # the defaults it gets
# The cart-pole of the checker's run: the paper's equations with masses, length and gravity
# other than the defaults, so that a node that keeps the defaults instead of reading the run's
# file is told. Force, tau and the limits stay the defaults: the harness and the rules use them.
RUN_PHYSICS = {"cart_mass": 0.9, "pole_mass": 0.15, "pole_length": 0.4, "gravity": 9.81}
CHECKED_RUN = Params(max_steps=MAX_STEPS, **RUN_PHYSICS)
UNITS = {"cart_mass": "kg", "pole_mass": "kg", "pole_length": "m", "gravity": "m/s^2"}
# A state follows the physics within this (relative, absolute): a node may work in radians.
PHYSICS_TOLERANCE = (1e-6, 1e-9)
TAU_NS = tick_nanoseconds(TAU)
TYPES = {topic: TOPIC_TYPES[topic] for topic in (STATE, CLOCK, TRIAL_EVENT, ACTION)}
SHOWN_PER_RULE = 3  # FAIL lines per rule; more problems are counted


class Abort(Exception):
    """The node stopped answering: the remaining rules cannot be checked."""


class Findings:
    """The problems found per rule (the first SHOWN_PER_RULE of each, the others counted) and
    the rules checked at all."""

    def __init__(self, strict_physics: bool = False):
        self.problems = {rule: [] for rule in {**RULES, **PHYSICS_RULE}}
        self.checked = set()
        self.more = {}  # rule: problems found beyond those shown
        self.strict_physics = strict_physics  # physics a rule, not advice

    def fail(self, rule: str, text: str) -> None:
        if text in self.problems[rule]:
            return
        if len(self.problems[rule]) < SHOWN_PER_RULE:
            self.problems[rule].append(text)
        else:
            self.more[rule] = self.more.get(rule, 0) + 1

    def fail_all(self, rule: str, problems: Iterable[str]) -> None:
        for text in problems:
            self.fail(rule, text)

    def not_checked(self, rule: str, why: str) -> None:
        """The rule was reached but could not be checked: a FAIL line that says why."""
        self.problems[rule].append(f"not checked: {why}")

    def report(self) -> bool:
        """A PASS, FAIL or SKIP line per rule (physics: WARN instead of FAIL unless strict);
        True when every rule passes."""
        ok = True
        for rule, meaning in {**RULES, **PHYSICS_RULE}.items():
            problems = self.problems[rule]
            binding = rule in RULES or self.strict_physics
            if rule not in self.checked:
                print(f"SKIP  {rule}: not checked (an earlier failure stopped the check)")
                ok = ok and not binding
            elif problems:
                ok = ok and not binding
                for text in problems:
                    print(f"{'FAIL' if binding else 'WARN'}  {rule}: {text}")
                if not binding:
                    print(f"WARN  {rule}: fine for a simulator of its own (gymnasium, friction, "
                          f"a robot); {STRICT_PHYSICS} makes this a FAIL")
                if self.more.get(rule):
                    print(f"FAIL  {rule}: ... and {self.more[rule]} more like these")
            else:
                print(f"PASS  {rule}: {meaning}")
        return ok


def check_state_of_the_tick(msg, tick: int, trial: int, after: str) -> Iterator[str]:
    """lockstep: the state that answers `after` is the state of `tick`, of the trial of the
    last START."""
    if msg.tick != tick:
        yield f"state tick {msg.tick} after {after}"
    if msg.trial != trial:
        yield f"state of tick {tick} has trial {msg.trial}, not {trial} (the trial of the last " \
              f"START)"


def check_finite(msg, tick: int) -> Iterator[str]:
    """failure: every number of the state is finite."""
    values = (msg.cart_position_m, msg.cart_velocity_m_per_s, msg.pole_angle_deg,
              msg.pole_angular_velocity_deg_per_s)
    if not all(math.isfinite(v) for v in values):
        yield f"state of tick {tick} is not finite: {values}"


def check_failure(msg) -> Iterator[str]:
    """failure: a state's failure is the limit it crossed exactly when it lies beyond the angle
    or the track limit, FAILURE_NONE otherwise."""
    angle, x = abs(msg.pole_angle_deg), abs(msg.cart_position_m)
    beyond = {FAILURE_POLE_ANGLE: angle > ANGLE_LIMIT_DEG, FAILURE_CART_POSITION: x > TRACK_LIMIT_M}
    where = f"angle {msg.pole_angle_deg:.3f} deg, x {msg.cart_position_m:.3f} m"
    if msg.failure in beyond:
        if not beyond[msg.failure]:
            yield f"failure {msg.failure} ({FAILURE_REASONS[msg.failure]}) but the state is " \
                  f"inside that limit ({where})"
    elif msg.failure != FAILURE_NONE:
        yield f"failure {msg.failure} is not 0 (none), 1 (pole_angle) or 2 (cart_position)"
    elif any(beyond.values()):
        yield f"state beyond a limit not reported as failed ({where})"


def check_reset(msg, angle: float, steps_before: int) -> Iterator[str]:
    """reset: the state after START(angle) is the cart at 0 and at rest, the pole at rest at
    `angle`, no successful step, not failed."""
    if msg.successful_steps != 0:
        yield f"successful_steps not reset at START (was {steps_before}, published " \
              f"{msg.successful_steps})"
    if msg.cart_position_m != 0.0 or msg.cart_velocity_m_per_s != 0.0:
        yield f"cart not at 0 and at rest after START (x {msg.cart_position_m:g} m, dx/dt " \
              f"{msg.cart_velocity_m_per_s:g})"
    if abs(msg.pole_angle_deg - angle) > 1e-9 or msg.pole_angular_velocity_deg_per_s != 0.0:
        yield f"pole not at rest at START's initial_angle_deg {angle:g} (angle " \
              f"{msg.pole_angle_deg:g} deg, rate {msg.pole_angular_velocity_deg_per_s:g} deg/s)"
    if msg.failure != FAILURE_NONE:
        yield "the state after START is failed"


def check_step_counted(msg, steps_before: int, tick: int, trial: int) -> Iterator[str]:
    """successful_steps: one more than before for a successful step, none for the failing one."""
    expected = steps_before + (msg.failure == FAILURE_NONE)
    if msg.successful_steps != expected:
        what = "counts the failing step" if msg.failure != FAILURE_NONE and \
            msg.successful_steps == steps_before + 1 else f"expected {expected}"
        yield f"successful_steps {msg.successful_steps} at tick {tick} of trial {trial}: {what}"


def check_capped(msg) -> Iterator[str]:
    """successful_steps: a trial never counts past max_steps."""
    if msg.successful_steps > MAX_STEPS:
        yield f"successful_steps {msg.successful_steps} passed max_steps {MAX_STEPS}"


def check_one_state_per_tick(states) -> Iterator[str]:
    """lockstep: no tick has two states."""
    seen = {}
    for msg in states:
        seen[msg.tick] = seen.get(msg.tick, 0) + 1
    for tick, count in sorted(seen.items()):
        if count > 1:
            yield f"publishes {count} states for tick {tick}"


def check_physics(steps, run: Params = CHECKED_RUN) -> Iterator[str]:
    """physics: each step (the state before, the force direction, the state after, its tick)
    is one step of the core's cart-pole (clnn_ros.core.physics) with the run's parameters; a
    problem names the first step that differs, and what the node seems to step instead."""
    wrong = [step for step in steps if not follows(step, run)]
    if not wrong:
        return
    before, direction, after, tick = wrong[0]
    expected = expected_state(before, direction, run)
    shown = ", ".join(f"{name} {got:.9g} (expected {want:.9g})" for name, got, want in zip(
        ("x", "dx/dt", "angle", "rate"), after, expected) if not close(got, want))
    guess = next((what for what, other in other_physics(run)
                  if all(follows(step, other) for step in steps)), None)
    instead = f"; it steps {guess}" if guess else ""
    yield f"{len(wrong)} of {len(steps)} steps do not follow the run's cart-pole " \
          f"({physics_summary(run)}): tick {tick}, {'+' if direction > 0 else '-'}F: " \
          f"{shown}{instead}"


def physics_summary(run: Params) -> str:
    """'physics paper, semi_implicit, cart_mass 0.9 kg, ...': what the checker's run gives."""
    return ", ".join([f"physics {run.physics}", run.integrator,
                      *(f"{name} {getattr(run, name):g} {UNITS[name]}" for name in RUN_PHYSICS)])


def expected_state(before, direction: int, run: Params) -> tuple:
    """The state after `before` (degrees, as messages carry it) under the run's physics."""
    radians = state_in_radians(run)
    start = start_in_units(before, False, radians)
    return in_degrees(*physics_step(*start, direction * run.force, physics_constants(run),
                                    radians)[:4], radians)


def close(got: float, want: float) -> bool:
    return math.isclose(got, want, rel_tol=PHYSICS_TOLERANCE[0], abs_tol=PHYSICS_TOLERANCE[1])


def follows(step, run: Params) -> bool:
    before, direction, after, _ = step
    return all(close(got, want) for got, want in zip(after, expected_state(before, direction,
                                                                           run)))


def other_physics(run: Params) -> Iterator[tuple[str, Params]]:
    """(what, the Params) of what a node may step instead of the run's cart-pole: a parameter of
    the run's file ignored (its default kept), all of them, another physics or integrator."""
    default = Params()
    for name in RUN_PHYSICS:
        yield f"{name} {getattr(default, name):g} {UNITS[name]} (the default), not the " \
              f"run's {getattr(run, name):g}", run.replace(**{name: getattr(default, name)})
    yield "the default cart-pole (it ignores the run's physics parameters)", \
        run.replace(**{name: getattr(default, name) for name in RUN_PHYSICS})
    for physics in PHYSICS:
        for integrator in INTEGRATORS:
            if (physics, integrator) != (run.physics, run.integrator):
                yield f"physics {physics}, integrator {integrator}, not the run's " \
                      f"{run.physics}, {run.integrator}", \
                    run.replace(physics=physics, integrator=integrator)
