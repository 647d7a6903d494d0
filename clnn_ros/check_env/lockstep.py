"""The checker's side of the lockstep: it sends what the trial manager and the agent would, in
the orders the contract allows, keeps the tick, trial and successful steps the node must be at,
and checks every observation the node publishes against the rules of an observation of its
task (rules.py)."""

from __future__ import annotations

from typing import Callable

from clnn_ros_msgs.msg import Observation, TrialEvent

from ..core.params import CARTPOLE, Params
from ..graph.fields import ACTION_NONE
from ..graph.names import STATE
from ..graph.task_description import Described
from .probe import QUIET_S, REPLY_S, Probe
from .rules import (Abort, Findings, check_observation, check_observation_of_the_tick,
                    check_reset, check_step_counted, check_termination, check_truncation)


class Lockstep:
    def __init__(self, probe: Probe, findings: Findings, task: Described, run: Params):
        self.probe, self.findings, self.node = probe, findings, probe.node
        self.task, self.run = task, run
        self.cartpole = task.task.name == CARTPOLE  # its values: x, x', theta deg, theta' deg/s
        self.n_actions = len(task.task.actions)
        self.tick = 0  # the tick whose observation comes next
        self.trial = 0
        self.steps = 0  # successful steps of the current trial, as the harness counts them
        self.last = None  # the last observation
        self.applied = set()  # the action indices an observation answered
        self.terminated = 0  # observations seen terminated
        # the cart-pole: (state before, force direction, state after, tick) of each step taken
        self.transitions: list[tuple[tuple, int, tuple, int]] = []

    @staticmethod
    def over(msg: Observation) -> bool:
        return msg.terminated or msg.truncated

    def quiet(self, rule: str, what: str) -> bool:
        """No observation may come now; True when none came."""
        seen = len(self.node.states)
        if self.probe.spin(QUIET_S, lambda: len(self.node.states) > seen):
            self.findings.fail(rule, f"{what} (published observation tick "
                                     f"{self.node.states[seen].tick})")
            self.follow(self.node.states[seen])
            return False
        return True

    def follow(self, msg: Observation) -> None:
        """An observation that came when it should not: the node has advanced; follow it."""
        self.tick = msg.tick + 1
        self.last = msg
        self.steps = msg.successful_steps
        self.trial = msg.trial

    def arrived(self, seen: int, seconds: float = REPLY_S) -> bool:
        return self.probe.spin(seconds, lambda: len(self.node.states) > seen)

    def await_state(self, after: str, seen: int | None = None) -> Observation:
        """The observation that answers `after` (the first after the `seen` first ones),
        checked; Abort if none comes."""
        seen = len(self.node.states) if seen is None else seen
        if not self.arrived(seen):
            self.findings.fail("lockstep", f"publishes no {STATE} after {after}"
                                           f"{self.probe.exit_status()}")
            raise Abort
        msg = self.node.states[seen]
        self.findings.checked.update(("observation", "termination", "truncation"))
        fail = self.findings.fail_all
        fail("lockstep", check_observation_of_the_tick(msg, self.tick, self.trial, after))
        fail("observation", check_observation(msg, self.task, self.run))
        fail("termination", check_termination(msg, self.task))
        fail("truncation", check_truncation(msg, self.task))
        self.terminated += msg.terminated
        self.last = msg
        self.tick += 1
        return msg

    def start(self, angle: float, order: str = "start first") -> Observation:
        """START(t) and clock(t) (order: "start first", "clock first", "start only" when
        clock(t) is out already, or "before ACTION_NONE": the last trial's ACTION_NONE comes
        after them): a new trial; checks the reset. `angle`: the cart-pole's initial angle (0 is
        sent for another task)."""
        angle = angle if self.cartpole else 0.0
        t, none_for = self.tick, self.tick - 1
        self.trial += 0 if t == 0 else 1
        after = f"START({t}) and clock({t})"
        seen = len(self.node.states)
        if order == "start first":
            self.node.event(TrialEvent.START, t, self.trial, angle)
            self.quiet("lockstep", f"publishes observation {t} on START({t}) without clock({t})")
            self.node.clock(t)
        else:
            if order in ("clock first", "before ACTION_NONE"):
                self.node.clock(t)
            self.node.event(TrialEvent.START, t, self.trial, angle)
        if order == "before ACTION_NONE" and not self.arrived(seen):
            self.node.action(none_for, self.trial - 1, ACTION_NONE)
            self.findings.fail("actions", f"publishes no {STATE} on {after} until the "
                                          f"ACTION_NONE of tick {none_for} comes (the agent's "
                                          f"answer may arrive after them)")
            none_for = None
        msg = self.await_state(after, seen)
        self.findings.checked.add("reset")
        self.findings.fail_all("reset", check_reset(msg, angle if self.cartpole else None,
                                                    self.steps))
        self.steps = 0
        if order == "before ACTION_NONE" and none_for is not None:
            self.node.action(none_for, self.trial - 1, ACTION_NONE)
            self.quiet("lockstep", f"publishes observation {self.tick} on the ACTION_NONE of "
                                   f"tick {none_for}, which came after START({t})")
        return msg

    def step(self, action: int, order: str = "both") -> Observation:
        """action(t-1) of index `action` and clock(t); `order`: "both", "action first" or
        "clock first" (probe that neither alone makes an observation), "action only" or "clock
        only" (the other is out)."""
        t, before = self.tick, self.last
        if order in ("action only", "clock only"):
            if order == "action only":
                self.node.action(t - 1, self.trial, action)
            else:
                self.node.clock(t)
        elif order == "action first":
            self.node.action(t - 1, self.trial, action)
            self.quiet("lockstep", f"publishes observation {t} on action({t - 1}) without "
                                   f"clock({t})")
            self.node.clock(t)
        elif order == "clock first":
            self.node.clock(t)
            self.quiet("lockstep", f"publishes observation {t} on clock({t}) before "
                                   f"action({t - 1})")
            self.node.action(t - 1, self.trial, action)
        else:
            self.node.action(t - 1, self.trial, action)
            self.node.clock(t)
        if self.tick != t:  # a quiet probe caught an early observation; the node has moved on
            return self.last
        msg = self.await_state(f"action {action} of tick {t - 1}")
        self.applied.add(action)
        self.findings.checked.update(("successful_steps", "actions"))
        self.findings.fail_all("successful_steps", check_step_counted(msg, self.steps))
        self.steps += not msg.terminated
        if self.cartpole and before is not None and before.tick == t - 1 and \
                before.trial == msg.trial and msg.tick == t and not self.over(before) and \
                len(before.values) == len(msg.values) == 4:
            self.cartpole_step(before, action, msg)
        return msg

    def cartpole_step(self, before: Observation, action: int, after: Observation) -> None:
        """The cart-pole: the step kept for the physics rule; a trial's first step, from rest,
        pushes the cart the action's way."""
        direction = 1 if action == 1 else -1
        self.transitions.append((tuple(before.values), direction, tuple(after.values),
                                 after.tick))
        if before.successful_steps == 0 and before.values[1] == 0.0 and \
                after.values[1] * direction <= 0:
            self.findings.fail("actions", f"action {action} ({'+' if direction > 0 else '-'}F) "
                                          f"from rest gives cart velocity "
                                          f"{after.values[1]:g} m/s at tick {after.tick}: "
                                          f"action 0 pushes toward -x, 1 toward +x")

    def expect_refusal(self, rule: str, send: Callable[[], object], what: str) -> None:
        """Send something bad with this tick's clock: no observation may come."""
        self.findings.checked.add(rule)
        send()
        self.quiet(rule, what)

    def end_trial(self) -> None:
        """The trial is over: the agent answers ACTION_NONE (no observation may follow by
        itself)."""
        self.node.action(self.tick - 1, self.trial, ACTION_NONE)
        self.quiet("truncation" if self.last is not None and self.last.truncated else "lockstep",
                   f"publishes observation {self.tick} on the ACTION_NONE of tick "
                   f"{self.tick - 1} without a START")

    def policy(self, msg: Observation) -> int:
        """The harness's actions: the cart-pole's controller pushes towards where the pole is
        falling; another task's actions are taken each in turn."""
        if self.cartpole and len(msg.values) == 4:
            return 1 if msg.values[2] + 0.5 * msg.values[3] > 0 else 0
        return self.tick % self.n_actions

    def check_every_action_applied(self) -> None:
        """actions: each index was answered with an observation."""
        missing = sorted(set(range(self.n_actions)) - self.applied)
        if missing:
            self.findings.not_checked("actions", f"action {missing[0]} was never taken (the "
                                                 f"trials ended before it)")
