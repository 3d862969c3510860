"""The C heap's handling of large blocks, for long per-frame jobs.

glibc's ``malloc`` maps a block of more than 128 KB straight from the system
(growing that limit to the largest block freed so far) and returns freed memory at
the top of its heap once more than twice that is free.  Per-frame image work
allocates and frees the same few 1 MB images (a 1280x720 frame, its inverse,
pyramid levels, blurs) frame after frame, so with the defaults each was mapped,
page-faulted in and unmapped again: ~500-800 page faults per frame of blob
detection, ~1 ms of system time (measured), and the threads of Detect Blobs
[Active Range] queue on the process's memory map for every fault.
:func:`keep_freed_memory` serves such blocks from the heap and keeps freed memory
for reuse instead.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import sys

#: Blocks up to this size come from the heap (glibc ``M_MMAP_THRESHOLD``).
MMAP_THRESHOLD = 16 << 20
#: Free memory kept at the heap's top before it is returned to the system (``M_TRIM_THRESHOLD``).
TRIM_THRESHOLD = 64 << 20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_done = False


def keep_freed_memory() -> bool:
    """Ask glibc to keep freed memory for reuse (once per process); False where there is no glibc.

    Costs at most :data:`TRIM_THRESHOLD` of memory not returned to the system
    per heap (one per thread that allocates, at most eight per core); blocks
    larger than :data:`MMAP_THRESHOLD` are still mapped and unmapped directly.
    """
    global _done
    if _done:
        return True
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False        # not glibc (musl has no mallopt)
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    _done = bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    return _done
