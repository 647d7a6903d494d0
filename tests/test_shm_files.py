"""What clnn_ros.rosenv reads of a process's shared-memory files (the supervisor's notes, and
which files are in use before any is removed): every file the process holds, though it opens
and closes other files meanwhile, as a Fast DDS node does all the time."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time
from typing import Iterator

import pytest

from clnn_ros.rosenv import (SETTLE_S, SHM, own_fast_dds_files, remove_unused_fast_dds_files,
                             removed_listening_ports, shm_files_in_use, shm_files_of)

READS = 1000
# Holds a Fast DDS lock file open and opens and closes 20 other files at a time, without end.
BUSY_HOLDER = """
import os, sys
held = open(sys.argv[1])
print("holding", flush=True)
while True:
    for fd in [os.open(os.devnull, os.O_RDONLY) for _ in range(20)]:
        os.close(fd)
"""


def test_a_file_held_open_is_seen_at_every_read_though_others_close_meanwhile(tmp_path):
    # Before the fix, a file closed between the listing of /proc/<pid>/fd and its reading
    # ended the whole read: measured, 6 and 24 of 1,000 reads missed the file, and about a
    # third of them beside a test run.
    segment = f"fastrtps_clnn_test_{os.getpid()}_{tmp_path.name}"
    lock = f"{segment}_el"
    for name in (segment, lock):
        open(os.path.join(SHM, name), "w").close()
    holder = subprocess.Popen([sys.executable, "-c", BUSY_HOLDER, os.path.join(SHM, lock)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "holding\n"
        missed_own = sum(segment not in own_fast_dds_files(holder.pid) for _ in range(READS))
        missed_in_use = sum(lock not in shm_files_of(holder.pid) for _ in range(READS))
    finally:
        holder.kill()
        holder.wait()
        for name in (segment, lock):
            os.unlink(os.path.join(SHM, name))
    assert (missed_own, missed_in_use) == (0, 0)


# Creates a file, waits, then maps it: a participant setting up its port, slowed down.
SLOW_CREATOR = """
import mmap, os, sys, time
fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT, 0o644)
os.ftruncate(fd, 4096)
print("created", flush=True)
time.sleep(float(sys.argv[2]))
mapped = mmap.mmap(fd, 4096)
print("mapped", flush=True)
sys.stdin.read()
"""


def test_a_file_being_set_up_is_kept_and_an_old_unused_one_is_removed(tmp_path):
    """A new file that its creator maps within SETTLE_S is not removed as unused (before,
    removed at once: the port of a participant starting beside a run's cleanup); an unused file
    is removed."""
    name = f"fastrtps_clnn_test_{os.getpid()}_{tmp_path.name}"
    path = os.path.join(SHM, name)
    creator = subprocess.Popen([sys.executable, "-c", SLOW_CREATOR, path, str(SETTLE_S / 4)],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert creator.stdout.readline() == "created\n"
        assert remove_unused_fast_dds_files({name}) == []
        assert os.path.exists(path)  # mapped meanwhile: in use
        assert creator.stdout.readline() == "mapped\n"
    finally:
        creator.kill()
        creator.wait()
    assert remove_unused_fast_dds_files({name}) == []
    assert not os.path.exists(path)  # unused once its creator ended: removed


@contextlib.contextmanager
def mapped_in_namespace(prefix: list[str], path: str) -> Iterator[subprocess.Popen]:
    """A process started under `prefix` (a namespace of its own) that has created and mapped
    `path` (in the /dev/shm it sees); on the way out it is ended and this /dev/shm's file
    removed (a failed assertion leaves no file behind)."""
    other = subprocess.Popen([*prefix, sys.executable, "-c", SLOW_CREATOR, path, "0"],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert other.stdout.readline() == "created\n"
        assert other.stdout.readline() == "mapped\n"
        yield other
    finally:
        other.kill()
        other.wait()
        if os.path.exists(path):
            os.unlink(path)


def test_a_file_of_the_same_name_in_another_dev_shm_does_not_keep_this_one(tmp_path,
                                                                          in_private_shm):
    """A process with a /dev/shm of its own maps a file of the same name: this /dev/shm's file
    is still unused, and removed (before, kept: a run's ports from 7000 up stayed behind when a
    run in another mount namespace used the same port numbers)."""
    if not in_private_shm:
        pytest.skip("no private /dev/shm can be made here")
    name = f"fastrtps_clnn_test_{os.getpid()}_{tmp_path.name}"
    path = os.path.join(SHM, name)
    open(path, "w").close()
    with mapped_in_namespace(in_private_shm, path) as other:
        assert name in shm_files_of(other.pid)  # its own file, by the same name
        assert name not in shm_files_in_use()
        assert remove_unused_fast_dds_files({name}) == []
        assert not os.path.exists(path)


def test_a_process_in_another_mount_namespace_on_this_dev_shm_keeps_its_file(tmp_path):
    """A process whose mount namespace is its own but whose /dev/shm is this one (as under
    `ip netns exec`, lab.two_hosts' other host) maps a file: it is in use and kept (before,
    removed: only processes of this mount namespace counted, so a run in a network namespace
    removed the live ports of runs beside it, whose port numbers it had used)."""
    other_namespace = ["unshare", "--mount"]
    if subprocess.run([*other_namespace, "true"], capture_output=True).returncode != 0:
        pytest.skip("no mount namespace can be made here")
    name = f"fastrtps_clnn_test_{os.getpid()}_{tmp_path.name}"
    path = os.path.join(SHM, name)
    with mapped_in_namespace(other_namespace, path) as other:
        assert os.readlink(f"/proc/{other.pid}/ns/mnt") != os.readlink("/proc/self/ns/mnt")
        assert name in shm_files_in_use()
        assert remove_unused_fast_dds_files({name}) == []
        assert os.path.exists(path)


# A listener as Fast DDS runs one: a thread named dds.shm.<port> with the port's file mapped.
LISTENER = """
import ctypes, mmap, sys
ctypes.CDLL(None).prctl(15, sys.argv[2].encode(), 0, 0, 0)  # PR_SET_NAME: this thread's name
with open(sys.argv[1], "r+b") as f:
    port = mmap.mmap(f.fileno(), 4096)
print("listening", flush=True)
sys.stdin.read()
"""


def test_a_listening_port_whose_file_was_removed_is_named(tmp_path):
    """rosenv.removed_listening_ports: a port file removed under its listener (Fast DDS made it
    anew: the listener hears nothing sent there) is named; one still there, or a removed file
    the process maps but does not listen on (a port it sends to), is not."""
    listened, sent_to = tmp_path / "fastrtps_port64999", tmp_path / "fastrtps_port64998"
    for path in (listened, sent_to):
        path.write_bytes(bytes(4096))
    listener = subprocess.Popen([sys.executable, "-c", LISTENER, str(listened),
                                 "dds.shm.64999"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                text=True)
    sender = subprocess.Popen([sys.executable, "-c", LISTENER, str(sent_to), "dds.shm.1"],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        for process in (listener, sender):
            assert process.stdout.readline() == "listening\n"
        assert removed_listening_ports(listener.pid) == []
        listened.unlink()
        sent_to.unlink()
        assert removed_listening_ports(listener.pid) == ["fastrtps_port64999"]
        assert removed_listening_ports(sender.pid) == []
    finally:
        for process in (listener, sender):
            process.communicate(timeout=30)
    assert removed_listening_ports(listener.pid) == []  # gone: nothing to say


def test_a_deaf_node_says_so_of_itself(tmp_path):
    """glue.own_deafness, the trial manager's addition to a stall: its own port removed under it."""
    port = tmp_path / "fastrtps_port64997"
    port.write_bytes(bytes(4096))
    deaf = """
import ctypes, mmap, os, sys
from clnn_ros.nodes.glue import own_deafness
ctypes.CDLL(None).prctl(15, b"dds.shm.64997", 0, 0, 0)
with open(sys.argv[1], "r+b") as f:
    port = mmap.mmap(f.fileno(), 4096)
print(repr(own_deafness()))
os.unlink(sys.argv[1])
print(own_deafness())
"""
    said = subprocess.run([sys.executable, "-c", deaf, str(port)], capture_output=True,
                          text=True, timeout=60)
    assert said.stdout.splitlines() == [
        "''", "; this node listens on shared-memory ports whose files were removed under it "
              "(fastrtps_port64997): what was sent there never reached it"], said.stderr


def test_the_mutex_of_a_port_in_use_is_kept(tmp_path):
    """A port's mutex is open only while a process opens the port: it is not removed as unused
    while the port itself is used (a node's cleanup on its way out removed the mutexes of its
    live peers' ports), and it is once the port is not."""
    port = f"fastrtps_clnn_test_{os.getpid()}_{tmp_path.name}"
    mutex = f"sem.{port}_mutex"
    for name in (port, mutex):
        with open(os.path.join(SHM, name), "wb") as f:
            f.write(bytes(4096))
    try:
        listener = subprocess.Popen([sys.executable, "-c", LISTENER, os.path.join(SHM, port),
                                     "clnn_test"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                    text=True)
        try:
            assert listener.stdout.readline() == "listening\n"
            time.sleep(SETTLE_S)  # both settled: only their use decides
            assert remove_unused_fast_dds_files({port, mutex}) == []
            assert os.path.exists(os.path.join(SHM, mutex))
        finally:
            listener.communicate(timeout=30)
        assert remove_unused_fast_dds_files({port, mutex}) == []
        assert not os.path.exists(os.path.join(SHM, port))
        assert not os.path.exists(os.path.join(SHM, mutex))
    finally:  # a failing run leaves nothing in the machine's /dev/shm either
        for name in (port, mutex):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(os.path.join(SHM, name))
