"""The trial manager's measure of its own running time (graph.lockstep.RunningTime), on clocks
the test sets: a paused process counts no more than the cap, a busy one its CPU time."""

from __future__ import annotations

from clnn_ros.graph.lockstep import RunningTime

CAP = 0.2


class Clocks:
    def __init__(self):
        self.wall = self.cpu = 0.0

    def advance(self, wall: float, cpu: float) -> None:
        self.wall += wall
        self.cpu += cpu


def running_time() -> tuple[RunningTime, Clocks]:
    clocks = Clocks()
    return RunningTime(CAP, clock=lambda: clocks.wall, cpu_time=lambda: clocks.cpu), clocks


def test_a_check_on_schedule_counts_its_wall_time():
    running, clocks = running_time()
    clocks.advance(wall=0.1, cpu=0.001)
    assert running.since_last_check() == 0.1


def test_a_paused_or_starved_process_counts_the_cap_only():
    running, clocks = running_time()
    clocks.advance(wall=30.0, cpu=0.0)  # SIGSTOP
    assert running.since_last_check() == CAP
    clocks.advance(wall=5.0, cpu=0.05)  # its timer late on a starved CPU
    assert running.since_last_check() == CAP


def test_a_busy_process_counts_the_cpu_time_it_used():
    """A trial manager flooded with messages to refuse runs its watchdog late, but it runs."""
    running, clocks = running_time()
    clocks.advance(wall=3.0, cpu=2.5)
    assert running.since_last_check() == 2.5
    clocks.advance(wall=1.0, cpu=1.6)  # its DDS threads too: never more than the wall time
    assert running.since_last_check() == 1.0
