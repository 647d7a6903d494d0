"""Session-wide test fixtures."""

import os
from pathlib import Path

import pytest

SHM = Path("/dev/shm")


def _fast_dds_files() -> set[str]:
    return {p.name for p in SHM.glob("*fastrtps_*")}


def _files_in_use() -> set[str]:
    """Names under /dev/shm that some process has mapped or open."""
    used = set()
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            used.update(line.rsplit("/dev/shm/", 1)[1].split()[0]
                        for line in (proc / "maps").read_text().splitlines() if "/dev/shm/" in line)
            for fd in (proc / "fd").iterdir():
                target = os.readlink(fd)
                if target.startswith("/dev/shm/"):
                    used.add(target[len("/dev/shm/"):])
        except OSError:
            continue  # the process ended, or is not ours to read
    return used


@pytest.fixture(scope="session", autouse=True)
def remove_shared_memory_of_killed_nodes():
    """Some tests SIGKILL a node on purpose; a killed process cannot remove its Fast DDS
    shared-memory files. At the end, remove those that appeared during the session and that no
    process uses any more (what Fast DDS's `fastdds shm clean` does)."""
    before = _fast_dds_files()
    yield
    for name in (_fast_dds_files() - before) - _files_in_use():
        (SHM / name).unlink(missing_ok=True)
