"""clnn_ros.shm_janitor, the cleanup that outlives a killed run_all: told the run's pids and
Fast DDS files and its work directory, at its stdin's end it waits for those processes, then
removes the files that no process uses and the directory; after `done` (run_all cleaned up
itself) it removes nothing."""

from __future__ import annotations

import os
import subprocess
import sys

SHM = "/dev/shm"


def janitor(lines: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "clnn_ros.shm_janitor"], capture_output=True,
                          text=True, input="".join(line + "\n" for line in lines), timeout=60)


def own_file(tmp_path, name: str) -> str:
    """A file of this test under /dev/shm, named as Fast DDS names its files."""
    full = f"fastrtps_clnn_test_{os.getpid()}_{tmp_path.name}_{name}"
    open(os.path.join(SHM, full), "w").close()
    return full


def test_at_the_end_of_its_input_it_removes_the_unused_files_after_the_children(tmp_path):
    unused, held = own_file(tmp_path, "unused"), own_file(tmp_path, "held")
    other = own_file(tmp_path, "not_told")
    workdir = tmp_path / "workdir"
    (workdir / "sub").mkdir(parents=True)
    (workdir / "sub" / "params.yaml").write_text("{}")
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(1.5)"])
    holder = open(os.path.join(SHM, held))  # in use by a live process (this one)
    try:
        result = janitor([f"pid {child.pid}", f"file {unused}", f"file {held}", f"dir {workdir}"])
        assert child.poll() is not None  # it waited for the child to end
        assert result.returncode == 0 and not result.stderr
        assert sorted(set(os.listdir(SHM)) & {unused, held, other}) == sorted([held, other])
        assert not workdir.exists()
    finally:
        holder.close()
        for name in (unused, held, other):
            if os.path.exists(os.path.join(SHM, name)):
                os.unlink(os.path.join(SHM, name))
        child.wait()


def test_after_done_it_removes_nothing(tmp_path):
    name = own_file(tmp_path, "kept")
    try:
        result = janitor([f"file {name}", f"dir {tmp_path}", "done"])
        assert result.returncode == 0 and os.path.exists(os.path.join(SHM, name))
        assert tmp_path.exists()
    finally:
        os.unlink(os.path.join(SHM, name))
