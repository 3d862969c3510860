"""carapost: an open-source re-creation of Vicon CaraPost."""

import os as _os

# Our linear algebra is thousands of tiny (3x3 .. 12x12) problems; OpenBLAS's thread
# pool makes those up to 100x slower on a busy 2-core machine.  Only a default: set
# the variable yourself to override (it takes effect only if numpy is not imported yet).
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

__version__ = "0.1.0"
