"""Environment defaults for every process the project starts, applied before rclpy loads (a
user's own setting wins): DDS discovery stays on the loopback interface, and Fast DDS takes
the project's profile (fastdds_profile.xml: a shared-memory port outlives a paused process)."""

import os
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE",
                      str(Path(__file__).with_name("fastdds_profile.xml")))


# Fast DDS numbers a domain's ports 7400 + 250 x domain: past 232 they pass 65535, and its
# participant prints so and ends the process with status 1, past any handler.
MAX_DOMAIN_ID = 232


def domain_id_problem() -> str | None:
    """Why ROS_DOMAIN_ID cannot be used, or None (unset or empty is rcl's default domain)."""
    value = os.environ.get("ROS_DOMAIN_ID", "")
    if value == "" or (value.isdigit() and int(value) <= MAX_DOMAIN_ID):
        return None
    return f"ROS_DOMAIN_ID {value!r} is not a domain: an integer from 0 to {MAX_DOMAIN_ID}"


SHM = "/dev/shm"
# Set by a supervisor (run_all) that removes its processes' leftover Fast DDS files itself: a
# node process then leaves the removal to it and ends sooner (a scan of every process and up to
# SETTLE_S of waiting, which counted against its grace to exit on a loaded machine).
SHM_CLEANED_BY_SUPERVISOR = "CLNN_ROS_SHM_CLEANED_BY_SUPERVISOR"


def fast_dds_shm_files() -> set[str]:
    """Names of Fast DDS shared-memory files (segments, port queues, their locks)."""
    try:
        return {name for name in os.listdir(SHM) if "fastrtps_" in name}
    except OSError:
        return set()


def shm_files_of(pid: int | str) -> set[str]:
    """Names under /dev/shm that process `pid` has mapped or open (empty if it is gone or not
    ours to read)."""
    used = set()
    try:
        with open(f"/proc/{pid}/maps") as maps:
            used.update(line.rsplit(SHM + "/", 1)[1].split()[0]
                        for line in maps if SHM + "/" in line)
        used |= _open_shm_files(pid)
    except OSError:
        pass  # the process ended, or is not ours to read
    return used


def _open_shm_files(pid: int | str) -> set[str]:
    names = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except FileNotFoundError:
            continue  # closed since the listing: the others are still read
        if target.startswith(SHM + "/"):
            names.add(target[len(SHM) + 1:])
    return names


def removed_listening_ports(pid: int | str) -> list[str]:
    """The shared-memory ports process `pid` listens on (a Fast DDS thread dds.shm.<port> each)
    whose files were removed under it: another participant judged the port unhealthy and made
    it anew (SharedMemGlobal.hpp, open_port), and what is sent there never reaches `pid`. Empty
    if none, or if the process is gone or not ours to read."""
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
        listened = set()
        for task in tasks:
            with open(f"/proc/{pid}/task/{task}/comm") as comm:
                thread = comm.read().strip()
            if thread.startswith("dds.shm.") and thread[8:].isdigit():
                listened.add(f"fastrtps_port{thread[8:]}")
        with open(f"/proc/{pid}/maps") as maps:
            removed = {Path(line.split()[5]).name for line in maps
                       if line.rstrip().endswith(" (deleted)") and len(line.split()) > 5}
    except OSError:
        return []  # the process (or a thread) ended, or is not ours to read
    return sorted(listened & removed)


def deafness(pid: int | str, who: str) -> str:
    """"<who> listens on shared-memory ports whose files were removed under it (...): what was
    sent there never reached it" if process `pid` does (removed_listening_ports), else ""."""
    removed = removed_listening_ports(pid)
    return f"{who} listens on shared-memory ports whose files were removed under it " \
           f"({', '.join(removed)}): what was sent there never reached it" if removed else ""


def own_fast_dds_files(pid: int | str) -> set[str]:
    """The Fast DDS files that belong to process `pid`: its segment and the ports it listens on,
    each known by the lock file it holds open (`<name>_el`, `<name>_sl`), with the port's
    mutex. (A process also maps its peers' segments and ports, to write to them: not its own.)"""
    try:
        locks = {name for name in _open_shm_files(pid)
                 if "fastrtps_" in name and name.endswith(("_el", "_sl"))}
    except OSError:
        return set()
    return _with_companions({name[:-3] for name in locks})


def _with_companions(bases: set[str]) -> set[str]:
    """Fast DDS segments or ports with their lock files and their mutex."""
    return {f"{base}{suffix}" for base in bases for suffix in ("", "_el", "_sl")} | \
        {f"sem.{base}_mutex" for base in bases}


def written_fast_dds_files(pid: int | str) -> set[str]:
    """This user's Fast DDS segments and ports that process `pid` has mapped or open, with their
    lock files and mutex: its own and its peers' (the ports it writes to). A peer's port can be
    left behind by this process: one that a killed peer could not remove, or one that a peer
    removed on its way out while this process was opening it to send, which re-creates it
    (Fast DDS 2.14; docs/ROS_GRAPH.md)."""
    bases = set()
    for name in shm_files_of(pid):
        if name.startswith("fastrtps_") and not name.endswith(("_el", "_sl")):
            try:
                if os.stat(os.path.join(SHM, name)).st_uid == os.getuid():
                    bases.add(name)
            except OSError:
                pass  # removed meanwhile
    return _with_companions(bases)


def domain_port_files(domain_id: int) -> set[str]:
    """The Fast DDS port files of ROS domain `domain_id` that exist, with their lock files and
    mutex: Fast DDS numbers a domain's ports 7400 + 250 x domain + 0..249."""
    first = 7400 + 250 * domain_id
    return _with_companions({name for name in fast_dds_shm_files()
                             if name.startswith("fastrtps_port") and name[13:].isdigit()
                             and first <= int(name[13:]) < first + 250})


def remove_files_of_dead_process(names: set[str]) -> list[str]:
    """Remove a dead process's own Fast DDS files at once, though its peers still map them: a
    peer that opens such a port again then creates a fresh one instead of waiting for the
    dead listener's health check (fastdds_profile.xml: 30 s). Returns the problems."""
    return _remove(names & fast_dds_shm_files())


def shm_files_in_use() -> set[str]:
    """Names under /dev/shm that some process has mapped or open. A Fast DDS file no process
    uses is left over by a process that was killed (`fastdds shm clean` removes those). Only
    the processes that see this /dev/shm count: one with a /dev/shm of its own (a container, a
    test's private one) has files of the same names (the ports from 7000 up), and its use of
    them kept this one's leftovers, measured. Whether a process sees this /dev/shm is told by
    the file system it finds there, not by its mount namespace: `ip netns exec` (a network
    namespace: another host in lab.two_hosts) gives a mount namespace of its own that shares
    /dev/shm, and a run there took the files of this namespace's live processes for unused."""
    used, ours = set(), _shm_seen_by("self")
    for pid in filter(str.isdigit, os.listdir("/proc")):
        if _shm_seen_by(pid) == ours:
            used |= shm_files_of(pid)
    return used


def _shm_seen_by(pid: int | str) -> tuple[int, int] | None:
    """The /dev/shm that process `pid` sees, as (device, inode), through its root."""
    try:
        seen = os.stat(f"/proc/{pid}/root{SHM}")
    except OSError:
        return None  # ended, or not ours to read
    return seen.st_dev, seen.st_ino


def unused_fast_dds_files(names: set[str] | None = None) -> set[str]:
    """The Fast DDS files (all, or those of `names` that exist) that no process uses: what
    killed processes left behind."""
    candidates = fast_dds_shm_files() if names is None else names & fast_dds_shm_files()
    in_use = shm_files_in_use()
    # A port's mutex (sem.<port>_mutex) is open only while a process opens the port, not while
    # it listens or sends: it stays while its port is used. Removed, the next opener makes a
    # new one, and two processes that open or rebuild the port at once are no longer kept apart.
    return {name for name in candidates - in_use
            if not (name.startswith("sem.") and name.endswith("_mutex")
                    and name[4:-6] in in_use)}


# A Fast DDS file is created, then mapped by its creator a moment later, and a new participant of
# any domain may create a file of a name just found unused (the ports from 7000 up are the whole
# machine's). So a file found unused that is younger than SETTLE_S is looked at again after it,
# and a file is removed only if it is still the one found unused (the same inode).
SETTLE_S = 1.0


def remove_unused_fast_dds_files(names: set[str] | None = None) -> list[str]:
    """Remove the Fast DDS files (all, or `names`) that no process uses, as `fastdds shm clean`
    does, but none that a new participant is setting up (SETTLE_S). Returns a line for each
    file that could not be removed (another user's, say)."""
    found = _inodes(unused_fast_dds_files(names))
    now = time.time()
    youngest = max((changed for _, changed in found.values()), default=0.0)
    if now - youngest < SETTLE_S:
        time.sleep(SETTLE_S - (now - youngest))
        still = _inodes(unused_fast_dds_files(set(found)))
        found = {name: key for name, key in still.items()
                 if key[0] == found[name][0]}
    return _remove({name for name, (inode, _) in found.items()
                    if _inodes({name}).get(name, (None,))[0] == inode})


def _inodes(names: set[str]) -> dict[str, tuple[int, float]]:
    """{name: (inode, time of its last change)} of those of `names` that exist."""
    found = {}
    for name in names:
        try:
            stat = os.stat(os.path.join(SHM, name))
        except OSError:
            continue  # removed meanwhile
        found[name] = (stat.st_ino, max(stat.st_ctime, stat.st_mtime))
    return found


def _remove(names: set[str]) -> list[str]:
    problems = []
    for name in sorted(names):
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
