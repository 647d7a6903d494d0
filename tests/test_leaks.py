"""Ten consecutive runs (of each kind) leave nothing behind (scripts/leak_check.py): no process, no Fast DDS
shared memory, no growth in open files, resident memory within the script's stated bound."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import free_domain_id

pytestmark = pytest.mark.ros  # every test here starts ROS / DDS
SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "leak_check.py"
DOMAIN_ID = free_domain_id()


def test_ten_runs_of_each_kind_leave_nothing(tmp_path, in_private_shm):
    # A private /dev/shm where allowed: only files of these runs can be counted as left over.
    result = subprocess.run(
        [*in_private_shm, sys.executable, str(SCRIPT),
         "--runs", "10", "--trials", "2", "--max-steps", "300"],
        env={**os.environ, "ROS_DOMAIN_ID": DOMAIN_ID, "ROS_LOG_DIR": str(tmp_path / "log"),
             "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
        capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    table = [line for line in result.stdout.splitlines() if " run " in line and ": exit " in line]
    assert len(table) == 20 and all(": exit 0," in line for line in table), table
    assert "leak_check: 10 process runs and 10 composed runs left nothing" in result.stdout
