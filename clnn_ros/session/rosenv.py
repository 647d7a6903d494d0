"""Environment defaults for every process the project starts, applied before rclpy loads (a
user's own setting wins): DDS stays on the loopback interface, over UDP alone (no shared memory:
nothing in /dev/shm), with the project's Fast DDS profile (fastdds_loopback.xml says why)."""

import os
from pathlib import Path

RANGE = "ROS_AUTOMATIC_DISCOVERY_RANGE"
PROFILES_FILE = "FASTRTPS_DEFAULT_PROFILES_FILE"
LOOPBACK_PROFILE = Path(__file__).with_name("fastdds_loopback.xml")
SUBNET_PROFILE = Path(__file__).with_name("fastdds_subnet.xml")
# Both profiles' participant lease: a process that ended unannounced leaves the ROS graph of the
# others this long after (tests/test_transport.py holds it to the files).
PARTICIPANT_LEASE_S = 180.0


def apply_defaults(environ=os.environ) -> None:
    """Set the discovery range and Fast DDS profile of this process and its children, unless
    the user chose a profile: LOCALHOST (or unset) becomes SYSTEM_DEFAULT with the loopback
    profile, because under LOCALHOST rmw_fastrtps adds shared memory whatever a profile says;
    SUBNET and SYSTEM_DEFAULT (the graph across hosts, docs/MULTI_HOST.md) get UDP on every
    interface; OFF, and LOCALHOST with ROS_STATIC_PEERS (which only rmw's LOCALHOST reads), stay
    rmw's, with the subnet profile's lease and heartbeat. A child of a process that applied
    them inherits the loopback profile with SYSTEM_DEFAULT: still loopback (and LOCALHOST set
    for it again is loopback too)."""
    profile = environ.get(PROFILES_FILE)
    if profile not in (None, str(LOOPBACK_PROFILE), str(SUBNET_PROFILE)):
        environ.setdefault(RANGE, "LOCALHOST")
        return
    chosen = environ.get(RANGE) or "LOCALHOST"
    if profile == str(LOOPBACK_PROFILE) and chosen == "SYSTEM_DEFAULT":
        chosen = "LOCALHOST"
    if chosen == "LOCALHOST" and not environ.get("ROS_STATIC_PEERS"):
        environ[RANGE], environ[PROFILES_FILE] = "SYSTEM_DEFAULT", str(LOOPBACK_PROFILE)
    else:
        environ[RANGE], environ[PROFILES_FILE] = chosen, str(SUBNET_PROFILE)


apply_defaults()


# Fast DDS numbers a domain's ports 7400 + 250 x domain: past 232 they pass 65535, and its
# participant prints so and ends the process with status 1, past any handler.
MAX_DOMAIN_ID = 232


def domain_id_problem() -> str | None:
    """Why ROS_DOMAIN_ID cannot be used, or None (unset or empty is rcl's default domain)."""
    value = os.environ.get("ROS_DOMAIN_ID", "")
    if value == "" or (value.isdigit() and int(value) <= MAX_DOMAIN_ID):
        return None
    return f"ROS_DOMAIN_ID {value!r} is not a domain: an integer from 0 to {MAX_DOMAIN_ID}"


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
