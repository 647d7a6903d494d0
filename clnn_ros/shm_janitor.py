"""The cleanup that outlives run_all: if run_all is killed (even with SIGKILL), its nodes end on
their stdin's end of file, but Fast DDS files that a node re-created for a peer that had already
left stay in /dev/shm, and run_all's work directory stays in the temp folder. run_all starts
this process in a session of its own and tells it, one line each on its stdin, the pids of its
children (`pid N`), the run's Fast DDS files (`file NAME`) and its work directory (`dir PATH`).
`done` means run_all cleaned up itself; an end of file without it means run_all is gone: then,
once the children have ended, the run's files that no process uses and the work directory are
removed.
"""

from __future__ import annotations

import shutil
import sys
import time

from .rosenv import remove_unused_fast_dds_files

CHILDREN_EXIT_S = 60.0  # nodes end within seconds of their stdin's end; a file in use is kept


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def main() -> int:
    pids, files, directories = set(), set(), set()
    for line in sys.stdin:
        kind, _, value = line.rstrip("\n").partition(" ")
        if kind == "done":
            return 0
        if kind == "pid":
            pids.add(int(value))
        elif kind == "file":
            files.add(value)
        elif kind == "dir":
            directories.add(value)
    deadline = time.monotonic() + CHILDREN_EXIT_S
    while any(map(alive, pids)) and time.monotonic() < deadline:
        time.sleep(0.1)
    for problem in remove_unused_fast_dds_files(files):
        print(f"run_all: warning: {problem}", file=sys.stderr)
    for directory in directories:
        shutil.rmtree(directory, ignore_errors=True)  # what the children wrote there is spent
    return 0


if __name__ == "__main__":
    sys.exit(main())
