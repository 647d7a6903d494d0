"""Which ticks a topic's messages cover, as ranges: what the recorder notes of each per-tick topic
and stores in the bag, and what run_all compares with the run's own count of ticks (the bag
holds what trials.csv holds, or the last line says which ticks it lacks). No ROS import."""

from __future__ import annotations

import bisect

# The bag's metadata record of the ticks each per-tick topic holds: {topic: JSON ranges}.
TICKS_RECORD = "clnn_ros_ticks"
# How far the run went, noted by run_all in the bag's metadata.yaml (custom_data) once the run has
# ended: the bag holds it even when the recorder missed the episode's end.
RUN_END_NOTE = "clnn_ros.run_end"              # the run's exit reason (summary.json's)
RUN_LAST_TICK_NOTE = "clnn_ros.run_last_tick"  # the last tick the run completed


class TickRanges:
    """Sorted, disjoint [first, last] ranges of ticks. Messages come in tick order, so the last
    range grows; a tick out of order (a gap filled late, a stale or forged one) is merged in."""

    def __init__(self, ranges: list[list[int]] | None = None):
        self.ranges = [list(r) for r in ranges or []]

    def add(self, tick: int) -> None:
        ranges = self.ranges
        if ranges and ranges[-1][0] <= tick <= ranges[-1][1] + 1:
            ranges[-1][1] = max(ranges[-1][1], tick)
            return
        at = bisect.bisect_left(ranges, [tick, tick])
        ranges.insert(at, [tick, tick])
        # merge with the neighbours it touches
        start = max(at - 1, 0)
        merged = []
        for first, last in ranges[start:at + 2]:
            if merged and first <= merged[-1][1] + 1:
                merged[-1][1] = max(merged[-1][1], last)
            else:
                merged.append([first, last])
        ranges[start:at + 2] = merged

    def missing(self, first: int, last: int) -> list[tuple[int, int]]:
        """The ranges of [first, last] that this holds no tick of."""
        gaps, expected = [], first
        for low, high in self.ranges:
            if high < expected:
                continue
            if low > last:
                break
            if low > expected:
                gaps.append((expected, low - 1))
            expected = high + 1
        if expected <= last:
            gaps.append((expected, last))
        return gaps


def describe_ranges(ranges: list[tuple[int, int]], most: int = 3) -> str:
    """'1119-1614, 2000' (at most `most` ranges, then how many more)."""
    shown = [f"{a}-{b}" if b > a else f"{a}" for a, b in ranges[:most]]
    more = f" and {len(ranges) - most} more ranges" if len(ranges) > most else ""
    return ", ".join(shown) + more
