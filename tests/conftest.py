"""Session-wide test fixtures."""

from pathlib import Path

import pytest

from clnn_ros.rosenv import SHM, fast_dds_shm_files, shm_files_in_use


@pytest.fixture(scope="session", autouse=True)
def remove_shared_memory_of_killed_nodes():
    """Some tests SIGKILL a node on purpose; a killed process cannot remove its Fast DDS
    shared-memory files. At the end, remove those that appeared during the session and that no
    process uses any more (what Fast DDS's `fastdds shm clean` does)."""
    before = fast_dds_shm_files()
    yield
    for name in (fast_dds_shm_files() - before) - shm_files_in_use():
        (Path(SHM) / name).unlink(missing_ok=True)
