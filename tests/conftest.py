"""Session-wide test fixtures."""

import os
import subprocess

import pytest

from clnn_ros.rosenv import fast_dds_shm_files, remove_unused_fast_dds_files


@pytest.fixture(scope="session")
def in_private_shm() -> list[str]:
    """A command prefix that runs a command with a /dev/shm of its own (only its files are
    there), or [] where mount namespaces are not allowed: then the shared /dev/shm is used and
    a file left over is one that is new and unused (remove_shared_memory_of_killed_nodes)."""
    prefix = ["unshare", "--mount", "sh", "-c", 'mount -t tmpfs tmpfs /dev/shm && exec "$@"', "_"]
    allowed = subprocess.run([*prefix, "true"], capture_output=True).returncode == 0
    return prefix if allowed else []


@pytest.fixture(scope="session", autouse=True)
def remove_shared_memory_of_killed_nodes():
    """Some tests SIGKILL a node on purpose; a killed process cannot remove its Fast DDS
    shared-memory files. At the end, remove those that appeared during the session and that no
    process uses any more (what Fast DDS's `fastdds shm clean` does)."""
    before = fast_dds_shm_files()
    yield
    remove_unused_fast_dds_files(fast_dds_shm_files() - before)


def ros_environment(domain_id: str, tmp_path_factory) -> dict:
    """The environment of a test module's ROS processes: its own domain, loopback discovery,
    ROS logs in a temporary folder."""
    return {**os.environ, "ROS_DOMAIN_ID": domain_id, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "ROS_LOG_DIR": str(tmp_path_factory.mktemp("ros_log"))}
