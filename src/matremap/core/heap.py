"""The C heap's thresholds for a process that draws probes with numpy (glibc only).

A fit on the embedded renderer allocates and frees arrays of a probe's pixels (a 128^2 probe's RGB float64 pixels
are 280 kB; a batch's evaluator temporaries up to a few MB) thousands of times. glibc's malloc serves blocks above
its mmap threshold (128 kB, then raised dynamically to the largest freed block) with fresh mappings, and gives the
top of its heap back to the system whenever more than twice that is free: every such array then comes back as
fresh pages, zeroed by the kernel on first touch. A coloured two-stage fit at 128^2 took ~1,100 page faults and
~1.3 ms of system time in its ~9 ms (benchmarks/throughput.py, issue 17). :func:`keep_heap` raises both thresholds
once per process (blocks below :data:`MMAP_THRESHOLD` come from the heap, which keeps up to
:data:`TRIM_THRESHOLD` of free memory): no page faults in a fit, a third less CPU time, the same numbers.

It changes the whole process's allocator, so it is skipped where the user tuned it (any ``MALLOC_*`` variable
set) or opted out (``MATREMAP_KEEP_HEAP=0``), and outside glibc.
"""

from __future__ import annotations

import ctypes
import os
import sys

#: glibc's mallopt parameters (malloc.h)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: blocks below this come from the heap: the evaluators' largest temporaries (2^21 elements of float64) are 16 MB
MMAP_THRESHOLD = 16 << 20
#: free memory at the heap's top kept rather than given back
TRIM_THRESHOLD = 64 << 20

_applied: list[bool] = []


def keep_heap() -> bool:
    """Raise glibc's mmap and trim thresholds for this process, once (see the module docstring); whether they
    are raised."""
    if not _applied:
        _applied.append(_set_thresholds())
    return _applied[0]


def _set_thresholds() -> bool:
    if not sys.platform.startswith("linux") or os.environ.get("MATREMAP_KEEP_HEAP", "1") == "0":
        return False
    if any(name.startswith("MALLOC_") for name in os.environ):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))


__all__ = ["MMAP_THRESHOLD", "TRIM_THRESHOLD", "keep_heap"]
