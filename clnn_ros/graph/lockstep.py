"""The lockstep's two helpers every node composes: the join of a tick's inputs, and the count of
refused messages with its throttled log. No ROS import: a node hands in its logger's method."""

from __future__ import annotations

import time
from typing import Callable

REFUSAL_LOG_S = 1.0  # at most one refusal line per topic per second (a flood fills no disk)


class Refusals:
    """Bad messages dropped (the node's state untouched), counted by (topic, kind): "content"
    for the topic's content rule, "tick" for its tick or its place in the protocol. The first
    refusal on a topic is logged at once, then at most one line per REFUSAL_LOG_S with the
    count."""

    def __init__(self, log_error: Callable[[str], None]):
        self.log_error = log_error
        self.counts = {}  # (topic, kind): count
        self.last = {}  # topic: "tick N: reason" of its last refusal
        self._unlogged = {}  # topic: (refusals not logged yet, when the last line was logged)

    def refuse(self, topic: str, msg, reason: str, kind: str = "tick") -> None:
        self.counts[topic, kind] = self.counts.get((topic, kind), 0) + 1
        tick = getattr(msg, "tick", "?")
        self.last[topic] = f"tick {tick}: {reason}"
        now = time.monotonic()
        unlogged, logged_at = self._unlogged.get(topic, (0, -REFUSAL_LOG_S))
        if now - logged_at < REFUSAL_LOG_S:
            self._unlogged[topic] = (unlogged + 1, logged_at)
            return
        more = f" (and {unlogged} more since the last line)" if unlogged else ""
        self.log_error(f"refused {topic} tick {tick}: {reason}{more}")
        self._unlogged[topic] = (0, now)

    def summary(self) -> str:
        """'refused N messages: topic (kind) count, ...' or ''."""
        if not self.counts:
            return ""
        parts = ", ".join(f"{topic} ({kind}) {count}"
                          for (topic, kind), count in sorted(self.counts.items()))
        return f"refused {sum(self.counts.values())} messages: {parts}"


class TickJoin:
    """The messages of the current tick, one from each input topic. When all are in, they go to
    `complete` together and the join moves to the next tick; a message of another tick, or a
    second one from the same topic, is refused."""

    def __init__(self, topics: tuple[str, ...], complete: Callable[[dict], None],
                 refusals: Refusals):
        self.topics, self.complete, self.refusals = topics, complete, refusals
        self.tick = 0
        self.inbox = {}

    def standing(self) -> tuple[int, list[str]]:
        """(the tick it is at, the topics of that tick it holds)."""
        return self.tick, list(self.inbox)

    def offer(self, topic: str, msg) -> bool:
        """Take `msg` into this tick's inbox; False (refused) if it does not belong there."""
        if msg.tick != self.tick:
            self.refusals.refuse(topic, msg, f"expected tick {self.tick}")
            return False
        if topic in self.inbox:
            self.refusals.refuse(topic, msg, f"a second message for tick {self.tick}")
            return False
        self.inbox[topic] = msg
        if len(self.inbox) == len(self.topics):
            inbox, self.inbox = self.inbox, {}
            self.tick += 1
            self.complete(inbox)
        return True


class RunningTime:
    """The time a watchdog counts toward a stall at each of its checks: the wall time since the
    last check, at most `cap` unless the process was busy meanwhile. A pause of the process
    (SIGSTOP, a starved CPU) is not the graph's stall; a process kept busy is running, even when
    the work (a flood of messages to refuse) keeps its watchdog's timer from running on time:
    then the CPU time it used counts."""

    def __init__(self, cap: float, clock: Callable[[], float] = time.monotonic,
                 cpu_time: Callable[[], float] = time.process_time):
        self.cap, self.clock, self.cpu_time = cap, clock, cpu_time
        self.wall, self.cpu = clock(), cpu_time()

    def since_last_check(self) -> float:
        wall, cpu = self.clock(), self.cpu_time()
        running = min(wall - self.wall, max(self.cap, cpu - self.cpu))
        self.wall, self.cpu = wall, cpu
        return running


def episode_end_problem(event_tick: int, current_tick: int) -> str | None:
    """EPISODE_END(e) is sent with e the tick the trial manager waits for (it holds all of tick
    e-1) or the tick it just completed (the episode's last), and no clock follows it: a node
    has finished tick e-1 and cannot finish tick e+1, so its current tick is e or e+1. Any other
    tick is a stale or forged end, or another graph's."""
    if event_tick in (current_tick - 1, current_tick):
        return None
    return f"EPISODE_END expected at tick {current_tick - 1} or {current_tick}"
