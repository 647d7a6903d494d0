"""The project's environment node, started once the file argv[1] exists: for a test that holds
a graph before its start (run_all --env-node "python gated_environment.py FILE").

    python gated_environment.py FILE [node arguments...]
"""

import os
import sys
import time

while not os.path.exists(sys.argv[1]):
    time.sleep(0.05)
os.execv(sys.executable, [sys.executable, "-m", "clnn_ros.nodes.environment", *sys.argv[2:]])
