#!/usr/bin/env bash
# Set up, then run the test suite. Extra arguments go to pytest.
# Two test files run at once (pytest-xdist): a ROS test spends much of its time waiting on its
# processes and on discovery, which another file's tests fill. CLNN_TEST_WORKERS=0: one at a time.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/venv_env.sh"
exec "$PYTHON" -m pytest -q -n "${CLNN_TEST_WORKERS:-2}" --dist loadfile "$@"
