# Sourced by run.sh and test.sh: set up (idempotent, fast when nothing changed), then prepare
# the environment the venv's python runs in. Defines ROOT and PYTHON.
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
# Keep DDS discovery on loopback unless the user chose otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
# Let the venv's ROS wheel bootstrapper set LD_LIBRARY_PATH for this venv.
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE
PYTHON="$ROOT/.venv/bin/python"
