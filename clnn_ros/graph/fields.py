"""Conventions of the graph's message fields and result files. No ROS import (nor numba), so
offline tools read them without loading rclpy; the .msg files in msgs_spec/ define the same
values, and tests/test_msgs.py checks that they agree."""

# TrialEvent.event
START, END, EPISODE_END = 0, 1, 2
# CartPoleState.failure_reason, by the physics status of core.physics (CONTINUE, FAIL_ANGLE,
# FAIL_POSITION): "" while the trial goes on.
FAILURE_REASONS = ("", "pole_angle", "cart_position")
# TrialEvent.end_reason of a trial that reached max_steps (one that failed: its failure_reason).
REACHED_MAX_STEPS = "max_steps"
# A trial's end reason by the physics status that ended it (CONTINUE: it reached max_steps).
END_REASONS = (REACHED_MAX_STEPS, *FAILURE_REASONS[1:])
# trials.csv, as the trial manager and analyze write it.
TRIALS_CSV_HEADER = ("seed", "trial", "initial_angle_deg", "steps", "end_reason")
