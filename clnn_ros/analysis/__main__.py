"""python -m clnn_ros.analysis BAG [...]: clnn-analyze, a recorded bag's results and pictures
(clnn_ros.analysis.analyze)."""

import sys

from .analyze import main

sys.exit(main())
