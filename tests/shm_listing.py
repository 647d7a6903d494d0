"""Run a command (in the test's private /dev/shm); when it has ended and so has every other
process of the run (those with the test's CLNN_TEST_RUN mark), write the names in /dev/shm to
the file $LISTING. The command's pid goes to $LISTING.pid, for the test to signal it."""

import os
import subprocess
import sys
import time

from clnn_ros.rosenv import processes_with_env

command = subprocess.Popen(sys.argv[1:])
with open(os.environ["LISTING"] + ".pid", "w") as pid_file:
    pid_file.write(str(command.pid))
code = command.wait()
deadline = time.monotonic() + 90  # the test's own bound; it asserts no process is left
while (set(processes_with_env("CLNN_TEST_RUN", os.environ["CLNN_TEST_RUN"])) - {os.getpid()}
       and time.monotonic() < deadline):
    time.sleep(0.1)
with open(os.environ["LISTING"], "w") as listing:
    listing.write("\n".join(sorted(os.listdir("/dev/shm"))))
sys.exit(code)
