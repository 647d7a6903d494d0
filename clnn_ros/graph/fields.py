"""Conventions of the graph's message fields and result files. No ROS import (nor numba), so
offline tools read them without loading rclpy; the .msg files in msgs_spec/ define the same
values, and tests/test_msgs.py checks that they agree."""

import csv
import io
import json

import numpy as np

# TrialEvent.event
START, END, EPISODE_END = 0, 1, 2
# The cart-pole's ways to terminate (its TaskDescription.termination_reasons): its
# Observation.termination is the physics status of core.physics (CONTINUE 0, FAIL_ANGLE 1,
# FAIL_POSITION 2), 1 + an index here; TrialEvent.end_reason and trials.csv write the name.
CARTPOLE_TERMINATIONS = ("pole_angle", "cart_position")
# TrialEvent.end_reason of a trial that was truncated (the cart-pole: it reached max_steps).
REACHED_MAX_STEPS = "max_steps"
# A cart-pole trial's end reason by the physics status that ended it (CONTINUE: max_steps).
END_REASONS = (REACHED_MAX_STEPS, *CARTPOLE_TERMINATIONS)
# Action.action of a trial's last tick: nothing is applied
ACTION_NONE = 255
# EPISODE_END's end_reason (and summary.json's exit_reason) of an episode that ran to its end.
COMPLETED = "completed"
# trials.csv, as the trial manager and analyze write it.
TRIALS_CSV_HEADER = ("seed", "trial", "initial_angle_deg", "steps", "end_reason")

NANOSECONDS = 1_000_000_000


def tick_nanoseconds(tau_s: float) -> int:
    """One tick of sim time in nanoseconds: every stamp of the graph is a whole multiple."""
    return round(tau_s * 1e9)


def tick_stamp(tick: int, tau_ns: int) -> tuple[int, int]:
    """(sec, nanosec) of the sim time of `tick`: its /clock (and its markers' stamp)."""
    return divmod(tick * tau_ns, NANOSECONDS)


def stamp_nanoseconds(sec: int, nanosec: int) -> int:
    return sec * NANOSECONDS + nanosec


def trials_csv(rows) -> str:
    """trials.csv's text: TRIALS_CSV_HEADER, then the rows (seed, trial, initial angle, steps,
    end reason), as the trial manager and analyze write it."""
    text = io.StringIO()
    writer = csv.writer(text)
    writer.writerow(TRIALS_CSV_HEADER)
    writer.writerows(rows)
    return text.getvalue()


def summary_json(seed: int, steps: list[int], ticks: int, wall_s: float, exit_reason: str,
                 exit_status: int) -> str:
    """summary.json's text, as the trial manager writes it and run_all reads it: `exit_status`
    is the status the trial manager exits with (run_all's, if it has to end the process)."""
    return json.dumps({"seed": seed, "trials": len(steps),
                       "mean_steps": float(np.mean(steps)) if steps else None,
                       "ticks": ticks, "wall_s": wall_s,
                       "ticks_per_s": ticks / wall_s if wall_s else None,
                       "exit_reason": exit_reason, "exit_status": exit_status}, indent=2)
