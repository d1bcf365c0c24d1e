"""Giving freed memory back to the operating system after a big load or build.

Loading a million-edge graph and building its engine allocate and free a few hundred MB of temporary
numpy arrays. glibc keeps freed blocks below its (self-raising, up to 32 MB) mmap threshold in the heap, so
the process kept ~150 MB it no longer used, and the next peak (the first step's scratch and trace rows) came
on top of it. `malloc_trim(0)` returns those pages; it takes milliseconds, so it runs only after big work.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import sys

# below this many facts / atoms the temporaries are small: not worth a call
BIG_WORK = 100_000

_trim = None
if sys.platform.startswith("linux"):
    try:
        _libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        _trim = _libc.malloc_trim  # glibc only; musl and others lack it
        _trim.argtypes = [ctypes.c_size_t]
        _trim.restype = ctypes.c_int
    except (OSError, AttributeError):
        _trim = None


def release_freed_memory(size: int) -> bool:
    """After work on `size` facts or atoms: return the heap's free pages to the OS (glibc), if the work
    was big. True if it ran."""
    if _trim is None or size < BIG_WORK:
        return False
    _trim(0)
    return True
