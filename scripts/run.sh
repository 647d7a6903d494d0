#!/usr/bin/env bash
# Set up (idempotent, fast when nothing changed), then run the main job: the ROS 2 graph
# (python -m clnn_ros.run_all), which learns one episode and prints a summary.
# Extra arguments go to run_all (see --help).
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
# Keep DDS discovery on loopback unless the user chose otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
# Let the venv's ROS wheel bootstrapper set LD_LIBRARY_PATH for this venv.
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE
exec "$ROOT/.venv/bin/python" -m clnn_ros.run_all "$@"
