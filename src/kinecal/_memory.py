"""Allocator settings for array-heavy runs (glibc's malloc on Linux).

A 7000-pose Jacobian is a handful of multi-megabyte arrays, allocated and freed on every
solver iteration. By default glibc serves such blocks with fresh ``mmap`` pages (or trims
the heap as soon as they are freed), so every iteration pays a page fault per 4 kB it
touches: on a 2-core VM that was half the time of a full-model Jacobian (46 -> 17 ms) and
of a 7000-pose calibration (5.0 -> 2.2 s). Keeping freed memory in the process avoids it;
the price is that the process holds on to its peak heap until it exits.

The ``kinecal`` command applies this at start; library users opt in with
:func:`keep_freed_memory` (it changes the whole process's allocator).
"""

from __future__ import annotations

import ctypes
import sys

__all__ = ["keep_freed_memory"]

# mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3

_applied: bool | None = None


def keep_freed_memory() -> bool:
    """Serve large arrays from the heap and keep freed memory for reuse (glibc only).

    Sets malloc's mmap threshold to 256 MB (32 MB where glibc caps it), its trim
    threshold to 1 GB and a 64 MB top pad. Idempotent.

    Returns
    -------
    bool
        True when the settings are in force; False on other platforms or C libraries
        (nothing changes there).
    """
    global _applied
    if _applied is not None:
        return _applied
    _applied = False
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # musl and others have no mallopt
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    ok = bool(
        mallopt(_M_MMAP_THRESHOLD, 256 << 20) or mallopt(_M_MMAP_THRESHOLD, 32 << 20)
    )
    ok = ok and bool(mallopt(_M_TRIM_THRESHOLD, 1 << 30))
    ok = ok and bool(mallopt(_M_TOP_PAD, 64 << 20))
    _applied = ok
    return ok
