#!/usr/bin/env bash
# Set up, then run the main job: the ROS 2 graph (python -m clnn_ros.run_all), which learns one
# episode and prints a summary. Extra arguments go to run_all (see --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/venv_env.sh"
exec "$PYTHON" -m clnn_ros.run_all "$@"
