"""The episode the checker plays against the node: a balancing trial up to the max_steps cap
with malformed inputs in between, a START outside the angle limit, a trial pushed with constant
+F until it fails, a short trial and EPISODE_END; then a second start whose stdin is closed."""

from __future__ import annotations

import subprocess

from clnn_ros_msgs.msg import TrialEvent

from ..graph.fields import FAILURE_NONE
from ..graph.names import STATE
from ..session.process_signals import EXIT_WITH_STDIN
from .interface import connect
from .lockstep import Lockstep
from .probe import APPEAR_S, EXIT_S, Probe
from .rules import (ANGLE_LIMIT_DEG, MAX_STEPS, NAME, Abort, Findings, check_capped,
                    check_one_state_per_tick, check_physics)


def run_checks(probe: Probe, strict_physics: bool = False) -> Findings:
    """Every rule of the contract checked against the probe's command (the physics: advice,
    unless `strict_physics`)."""
    findings = Findings(strict_physics)
    with probe.session():
        probe.start_process()
        play = None
        try:
            connect(probe, findings)
            play = Lockstep(probe, findings)
            play_episode(play)
        except Abort:
            pass
        finally:
            probe.stop_process()
        if play is not None and play.transitions:
            findings.checked.add("physics")
            findings.fail_all("physics", check_physics(play.transitions))
        if not findings.problems["starts"]:
            check_stdin_eof(probe, findings)
        states = list(probe.node.states)
    findings.fail_all("lockstep", check_one_state_per_tick(states))
    return findings


def play_episode(play: Lockstep) -> None:
    node = play.node
    play.quiet("lockstep", f"publishes {STATE} before any clock or START")
    msg = play.start(1.0)
    # trial 0: balance up to the cap, probing the tick protocol and the refusals
    bad_inputs = {  # tick: (send a bad input with clock(t), what taking it means)
        5: (lambda t: node.action(t - 1, play.trial, 5),
            "does not refuse an action with force_direction 5"),
        6: (lambda t: node.action(t + 3, play.trial, 1),
            "does not refuse an action of tick 9 at tick 6 (expected tick 5)"),
        7: (lambda t: node.event(TrialEvent.START, t, play.trial + 1, 0.5),
            "does not refuse a START in the middle of a trial"),
    }
    while msg.failure == FAILURE_NONE and play.steps < MAX_STEPS:
        t = play.tick
        direction = play.balance(msg)
        order = {1: "action first", 2: "clock first"}.get(t, "both")
        if t in bad_inputs:
            send, what = bad_inputs[t]
            play.expect_refusal("refusals", lambda: (send(t), node.clock(t)), what)
            order = "action only"
        elif t == 8:
            play.expect_refusal("refusals", lambda: (node.clock(t + 3),
                                                     node.action(t - 1, play.trial, direction)),
                                f"does not refuse clock of tick {t + 3} at tick {t}")
            order = "clock only"
        if play.tick != t:  # it took the bad input and published a state: follow it
            msg = play.last
            continue
        msg = play.step(direction, order)
    if msg.failure != FAILURE_NONE:
        play.findings.not_checked(
            "successful_steps", f"the checker's controller kept the pole up for only "
                                f"{msg.successful_steps} of the max_steps {MAX_STEPS} steps")
    else:
        play.findings.fail_all("successful_steps", check_capped(msg))
    play.end_trial()
    angle, t = ANGLE_LIMIT_DEG + 18.0, play.tick
    play.expect_refusal("refusals", lambda: (node.event(TrialEvent.START, t, play.trial + 1,
                                                        angle), node.clock(t)),
                        f"does not refuse a START with initial_angle_deg {angle:g} (outside "
                        f"+-{ANGLE_LIMIT_DEG:g})")
    if play.tick != t:  # it took that START: end that trial too
        play.end_trial()
    # trial 1: constant +F until the trial fails
    msg = play.start(-0.5, "start only" if play.tick == t else "clock first")
    while msg.failure == FAILURE_NONE and play.steps < MAX_STEPS:
        msg = play.step(1)
    play.findings.checked.add("failure")
    if msg.failure == FAILURE_NONE:
        play.findings.fail("failure", f"constant +F for max_steps {MAX_STEPS} steps did not "
                                      f"fail the trial (pole at {msg.pole_angle_deg:.2f} deg, "
                                      f"cart at {msg.cart_position_m:.2f} m)")
    play.end_trial()
    # trial 2: a few steps, then the end of the episode
    msg = play.start(0.25)
    for _ in range(3):
        msg = play.step(play.balance(msg))
    node.event(TrialEvent.EPISODE_END, play.tick - 1, play.trial)
    check_episode_end(play.probe, play.findings)


def check_episode_end(probe: Probe, findings: Findings) -> None:
    """episode_end: on EPISODE_END the node exits, with status 0."""
    findings.checked.add("episode_end")
    try:
        status = probe.process.wait(timeout=EXIT_S)
    except subprocess.TimeoutExpired:
        findings.fail("episode_end", f"does not exit on EPISODE_END (still running after "
                                     f"{EXIT_S:g} s)")
    else:
        if status != 0:
            findings.fail("episode_end", f"exits with status {status} on EPISODE_END")


def check_stdin_eof(probe: Probe, findings: Findings) -> None:
    """stdin_eof: started again, once its node is in the graph its stdin is closed; it must
    exit."""
    probe.spin(EXIT_S, lambda: not probe.environment_present())  # the first one is gone
    findings.checked.add("stdin_eof")
    probe.start_process()
    appear_s = max(probe.startup_s, APPEAR_S)
    if not probe.spin(appear_s, probe.environment_present):
        if probe.process.poll() is not None:
            findings.fail("stdin_eof", f"started again, it exited with status "
                                       f"{probe.process.returncode} before its stdin was closed")
        else:
            findings.fail("stdin_eof", f"started again, no node '{NAME}' appeared within "
                                       f"{appear_s:g} s")
        return
    probe.process.stdin.close()
    try:
        probe.process.wait(timeout=EXIT_S)
    except subprocess.TimeoutExpired:
        findings.fail("stdin_eof", f"does not exit when its stdin reaches end of file (still "
                                   f"running after {EXIT_S:g} s; run_all gives every node a pipe "
                                   f"on stdin and {EXIT_WITH_STDIN}=1)")
