"""The checker's side of the lockstep: it sends what the trial manager and the agent would, in
the orders the contract allows, keeps the tick, trial and successful steps the node must be at,
and checks every state the node publishes against the rules of a state (rules.py)."""

from __future__ import annotations

from typing import Callable

from clnn_ros_msgs.msg import CartPoleState, TrialEvent

from ..graph.fields import FAILURE_NONE
from ..graph.names import STATE
from .probe import QUIET_S, REPLY_S, Probe
from .rules import (Abort, Findings, check_failure, check_finite, check_reset,
                    check_state_of_the_tick, check_step_counted)


class Lockstep:
    def __init__(self, probe: Probe, findings: Findings):
        self.probe, self.findings, self.node = probe, findings, probe.node
        self.tick = 0  # the tick whose state comes next
        self.trial = 0
        self.steps = 0  # successful steps of the current trial, as the harness counts them
        self.last = None  # the last state
        # (state before, force direction, state after, tick) of each step taken as sent
        self.transitions: list[tuple[tuple, int, tuple, int]] = []

    def quiet(self, rule: str, what: str) -> bool:
        """No state may come now; True when none came."""
        seen = len(self.node.states)
        if self.probe.spin(QUIET_S, lambda: len(self.node.states) > seen):
            self.findings.fail(rule, f"{what} (published state tick {self.node.states[seen].tick})")
            self.follow(self.node.states[seen])
            return False
        return True

    def follow(self, msg: CartPoleState) -> None:
        """A state that came when it should not: the node has advanced; follow it."""
        self.tick = msg.tick + 1
        self.last = msg
        self.steps = msg.successful_steps
        self.trial = msg.trial

    def await_state(self, after: str) -> CartPoleState:
        """The state that answers `after`, checked; Abort if none comes."""
        seen = len(self.node.states)
        if not self.probe.spin(REPLY_S, lambda: len(self.node.states) > seen):
            self.findings.fail("lockstep", f"publishes no {STATE} after {after}"
                                           f"{self.probe.exit_status()}")
            raise Abort
        msg = self.node.states[seen]
        self.findings.fail_all("lockstep", check_state_of_the_tick(msg, self.tick, self.trial,
                                                                   after))
        self.findings.fail_all("failure", check_finite(msg, self.tick))
        self.findings.fail_all("failure", check_failure(msg))
        self.last = msg
        self.tick += 1
        return msg

    def start(self, angle: float, order: str = "start first") -> CartPoleState:
        """START(t) and clock(t) (order: "start first", "clock first", or "start only" when
        clock(t) is out already): a new trial; checks the reset."""
        self.trial += 0 if self.tick == 0 else 1
        if order == "start first":
            self.node.event(TrialEvent.START, self.tick, self.trial, angle)
            self.quiet("lockstep", f"publishes state {self.tick} on START({self.tick}) "
                                   f"without clock({self.tick})")
            self.node.clock(self.tick)
        else:
            if order == "clock first":
                self.node.clock(self.tick)
            self.node.event(TrialEvent.START, self.tick, self.trial, angle)
        msg = self.await_state(f"START({self.tick}) and clock({self.tick})")
        self.findings.checked.add("reset")
        self.findings.fail_all("reset", check_reset(msg, angle, self.steps))
        self.steps = 0
        return msg

    def step(self, direction: int, order: str = "both") -> CartPoleState:
        """action(t-1) and clock(t); `order`: "both", "action first" or "clock first" (probe
        that neither alone makes a state), "action only" or "clock only" (the other is out)."""
        t, before = self.tick, self.last
        if order in ("action only", "clock only"):
            if order == "action only":
                self.node.action(t - 1, self.trial, direction)
            else:
                self.node.clock(t)
        elif order == "action first":
            self.node.action(t - 1, self.trial, direction)
            self.quiet("lockstep", f"publishes state {t} on action({t - 1}) without clock({t})")
            self.node.clock(t)
        elif order == "clock first":
            self.node.clock(t)
            self.quiet("lockstep", f"publishes state {t} on clock({t}) before action({t - 1})")
            self.node.action(t - 1, self.trial, direction)
        else:
            self.node.action(t - 1, self.trial, direction)
            self.node.clock(t)
        if self.tick != t:  # a quiet probe caught an early state; the node has moved on
            return self.last
        msg = self.await_state(f"action of tick {t - 1}")
        self.findings.checked.add("successful_steps")
        self.findings.fail_all("successful_steps", check_step_counted(msg, self.steps, t,
                                                                      self.trial))
        self.steps += msg.failure == FAILURE_NONE
        if before is not None and before.tick == t - 1 and before.trial == msg.trial and \
                msg.tick == t and before.failure == FAILURE_NONE:
            self.transitions.append((values(before), direction, values(msg), t))
        return msg

    def expect_refusal(self, rule: str, send: Callable[[], object], what: str) -> None:
        """Send something bad with this tick's clock: no state may come."""
        self.findings.checked.add(rule)
        send()
        self.quiet(rule, what)

    def end_trial(self) -> None:
        """The trial is over: the agent answers force 0 (no state may follow by itself)."""
        self.node.action(self.tick - 1, self.trial, 0)
        self.quiet("lockstep", f"publishes state {self.tick} on the force-0 action of tick "
                               f"{self.tick - 1} without a START")

    @staticmethod
    def balance(msg: CartPoleState) -> int:
        """The harness's controller: push towards where the pole is falling."""
        return 1 if msg.pole_angle_deg + 0.5 * msg.pole_angular_velocity_deg_per_s > 0 else -1


def values(msg: CartPoleState) -> tuple:
    """The state as the core's cart-pole keeps it: x m, dx/dt m/s, angle deg, rate deg/s."""
    return (msg.cart_position_m, msg.cart_velocity_m_per_s, msg.pole_angle_deg,
            msg.pole_angular_velocity_deg_per_s)
