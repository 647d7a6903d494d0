"""The episode the checker plays against the node: a trial up to the max_steps cap with
malformed inputs in between, (the cart-pole: a START outside the angle limit), a trial with the
last action held until it terminates, a short trial that takes every action, EPISODE_END; then
a second start whose stdin is closed."""

from __future__ import annotations

import subprocess

from clnn_ros_msgs.msg import TrialEvent

from ..core.params import Params
from ..graph.fields import ACTION_NONE
from ..graph.names import STATE
from ..session.process_signals import EXIT_WITH_STDIN
from .interface import connect
from .lockstep import Lockstep
from .probe import APPEAR_S, EXIT_S, Probe
from .rules import (ANGLE_LIMIT_DEG, MAX_STEPS, NAME, Abort, Findings,
                    check_one_observation_per_tick, check_physics)


def run_checks(probe: Probe, run: Params, strict_physics: bool = False) -> Findings:
    """Every rule of the contract checked against the probe's command, in the checker's `run`
    (the physics: advice, unless `strict_physics`; the cart-pole's only)."""
    findings = Findings(strict_physics)
    with probe.session():
        probe.start_process()
        play = None
        try:
            task = connect(probe, findings, run)
            play = Lockstep(probe, findings, task, run)
            play_episode(play)
        except Abort:
            pass
        finally:
            probe.stop_process()
        if play is not None and not play.cartpole:
            findings.physics_skipped = f"the task is {play.task.task.name}, not the cart-pole"
        elif play is not None and play.transitions:
            findings.checked.add("physics")
            findings.fail_all("physics", check_physics(play.transitions, run))
        if not findings.problems["starts"] and not findings.older:
            check_stdin_eof(probe, findings)
        states = list(probe.node.states)
    findings.fail_all("lockstep", check_one_observation_per_tick(states))
    return findings


def play_episode(play: Lockstep) -> None:
    node, last = play.node, play.n_actions - 1
    play.quiet("lockstep", f"publishes {STATE} before any clock or START")
    msg = play.start(1.0)
    # trial 0: up to the cap, probing the tick protocol and the refusals
    bad_inputs = {  # tick: (send a bad input with clock(t), what taking it means)
        5: (lambda t: node.action(t - 1, play.trial, play.n_actions),
            f"does not refuse action {play.n_actions} (the task has {play.n_actions} actions)"),
        6: (lambda t: node.action(t + 3, play.trial, 0),
            "does not refuse an action of tick 9 at tick 6 (expected tick 5)"),
        7: (lambda t: node.event(TrialEvent.START, t, play.trial + 1, 0.5 * play.cartpole),
            "does not refuse a START in the middle of a trial"),
        9: (lambda t: node.action(t - 1, play.trial, ACTION_NONE),
            "does not refuse ACTION_NONE in the middle of a trial"),
    }
    while not play.over(msg) and play.steps < MAX_STEPS:
        t = play.tick
        action = play.policy(msg)
        order = {1: "action first", 2: "clock first"}.get(t, "both")
        if t in bad_inputs:
            send, what = bad_inputs[t]
            play.expect_refusal("refusals", lambda: (send(t), node.clock(t)), what)
            order = "action only"
        elif t == 8:
            play.expect_refusal("refusals", lambda: (node.clock(t + 3),
                                                     node.action(t - 1, play.trial, action)),
                                f"does not refuse clock of tick {t + 3} at tick {t}")
            order = "clock only"
        if play.tick != t:  # it took the bad input and published an observation: follow it
            msg = play.last
            continue
        msg = play.step(action, order)
    if msg.terminated and play.cartpole:  # its controller balances: the cap must be reached
        play.findings.not_checked(
            "truncation", f"the checker's controller ended trial 0 (terminated) after "
                          f"{msg.successful_steps} of the max_steps {MAX_STEPS} steps")
    elif msg.terminated:  # another task may end sooner under any actions: said, not failed
        play.findings.notes["truncation"] = f"trial 0 terminated after {msg.successful_steps} " \
                                            f"steps under the checker's actions: no truncation " \
                                            f"seen (every observation: never before max_steps " \
                                            f"{MAX_STEPS}, never past it)"
    play.end_trial()
    t = play.tick
    if play.cartpole:
        angle = ANGLE_LIMIT_DEG + 18.0
        play.expect_refusal("refusals", lambda: (node.event(TrialEvent.START, t, play.trial + 1,
                                                            angle), node.clock(t)),
                            f"does not refuse a START with initial_angle_deg {angle:g} "
                            f"(outside +-{ANGLE_LIMIT_DEG:g})")
        if play.tick != t:  # it took that START: end that trial too
            play.end_trial()
    # trial 1: the last action (the cart-pole: +F) until the trial terminates
    msg = play.start(-0.5, "start only" if play.cartpole and play.tick == t else "clock first")
    while not play.over(msg) and play.steps < MAX_STEPS:
        msg = play.step(last)
    if play.cartpole and not msg.terminated:
        play.findings.fail("termination", f"constant +F did not terminate trial {play.trial}: "
                                          f"it {'was truncated' if msg.truncated else 'went on'} "
                                          f"after {play.steps} steps (max_steps {MAX_STEPS}), "
                                          f"values {list(msg.values)}")
    # trial 2: every action in turn, then the end of the episode; its START comes before the
    # last trial's ACTION_NONE, as it may in a graph
    msg = play.start(0.25, "before ACTION_NONE")
    for action in range(max(3, play.n_actions)):
        if play.over(msg):
            break
        msg = play.step(action % play.n_actions)
    play.check_every_action_applied()
    if not play.terminated:
        play.findings.notes["termination"] = f"no trial terminated within max_steps " \
                                             f"{MAX_STEPS}: a terminating observation was not " \
                                             f"seen"
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
