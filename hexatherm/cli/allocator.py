"""The C allocator while a command computes: freed memory kept for the next array.

glibc's ``malloc`` gives every block above its mmap threshold (128 kB at first, raised
up to 32 MB as such blocks are freed) pages of its own from the kernel and hands them
back when the block is freed; it also hands back the top of its heap once more than
twice that is free there. numpy takes its arrays from ``malloc``, so each large array
a command makes (the points file read at once, the uncertainty's Jacobian, the results'
columns) is paged in afresh: a page fault and a page of zeros for every 4 kB written
the first time, paid as system time. ``process`` of 10,000 targets took 8,000-17,000
such faults in the uncertainty alone, 0.35-0.5 s of system time on a loaded machine
(about a third of its CPU there), and the reading's 230 MB twice over (issue 37).

:func:`keep_freed_memory` raises both thresholds to :data:`KEPT_BYTES` for the
commands that compute (:data:`LONG_LIVED` ones, which run for hours, keep the
defaults): arrays come from the heap, and what a step frees is handed to the next
step's arrays without going back to the kernel. The peak resident memory is about
the same (the freed pages are reused rather than taken again; the 10,000-target
``process`` measured 1-3 % above). Nothing is computed differently. A user who sets
the allocator's own variables (``GLIBC_TUNABLES``, ``MALLOC_MMAP_THRESHOLD_``,
``MALLOC_TRIM_THRESHOLD_``) keeps them; on a C library other than glibc nothing is
done.
"""

from __future__ import annotations

import ctypes
import os
import sys

#: ``mallopt`` parameters (glibc's malloc.h)
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
#: both thresholds: blocks up to this come from the heap, and up to this much free at
#: its top stays there
KEPT_BYTES = 1 << 30
#: the commands that run for hours (a server, a machine driven or recorded): the
#: allocator's defaults, which give memory back
LONG_LIVED = frozenset({"serve-twin", "run", "acquire"})
#: the environment's own settings of the allocator, which are left alone
ALLOCATOR_VARIABLES = ("GLIBC_TUNABLES", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_")


def keep_freed_memory(command: str | None) -> bool:
    """Keep freed memory in the heap for ``command``'s arrays (see the module's
    docstring); whether the thresholds were set."""
    if command in LONG_LIVED or not sys.platform.startswith("linux"):
        return False
    if any(name in os.environ for name in ALLOCATOR_VARIABLES):
        return False
    try:
        libc = ctypes.CDLL(None)  # the process's own symbols: its C library's
        version = libc.gnu_get_libc_version  # glibc's alone
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    version.restype = ctypes.c_char_p
    if not version():
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    return bool(mallopt(M_MMAP_THRESHOLD, KEPT_BYTES)) & bool(mallopt(M_TRIM_THRESHOLD, KEPT_BYTES))
