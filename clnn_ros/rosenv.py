"""Environment defaults for every process the project starts, applied before rclpy loads:
DDS discovery stays on the loopback interface unless the user chose otherwise."""

import os

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


SHM = "/dev/shm"


def fast_dds_shm_files() -> set[str]:
    """Names of Fast DDS shared-memory files (segments, port queues, their locks)."""
    return {name for name in os.listdir(SHM) if "fastrtps_" in name}


def shm_files_of(pid: int | str) -> set[str]:
    """Names under /dev/shm that process `pid` has mapped or open (empty if it is gone or not
    ours to read)."""
    used = set()
    try:
        with open(f"/proc/{pid}/maps") as maps:
            used.update(line.rsplit(SHM + "/", 1)[1].split()[0]
                        for line in maps if SHM + "/" in line)
        for fd in os.listdir(f"/proc/{pid}/fd"):
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
            if target.startswith(SHM + "/"):
                used.add(target[len(SHM) + 1:])
    except OSError:
        pass  # the process ended, or is not ours to read
    return used


def shm_files_in_use() -> set[str]:
    """Names under /dev/shm that some process has mapped or open. A Fast DDS file no process
    uses is left over by a process that was killed (`fastdds shm clean` removes those)."""
    used = set()
    for pid in filter(str.isdigit, os.listdir("/proc")):
        used |= shm_files_of(pid)
    return used


def remove_unused_fast_dds_files(names: set[str] | None = None) -> list[str]:
    """Remove the Fast DDS files (all, or `names`) that no process uses, as `fastdds shm clean`
    does: what killed processes left behind. Returns a line for each file that could not be
    removed (another user's, say)."""
    problems = []
    candidates = fast_dds_shm_files() if names is None else names & fast_dds_shm_files()
    for name in candidates - shm_files_in_use():
        try:
            os.unlink(os.path.join(SHM, name))
        except FileNotFoundError:
            pass  # removed meanwhile
        except OSError as error:
            problems.append(f"cannot remove {SHM}/{name}: {error.strerror}")
    return problems


def processes_with_env(name: str, value: str) -> list[int]:
    """PIDs of the processes whose environment holds name=value (a run marks its processes so)."""
    entry, found = f"{name}={value}\0".encode(), []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/environ", "rb") as environ:
                if entry in environ.read():
                    found.append(int(pid))
        except OSError:
            continue  # ended meanwhile, or not ours to read
    return found
