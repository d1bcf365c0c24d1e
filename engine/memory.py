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
from functools import cache
from typing import Any

# below this many facts / atoms the temporaries are small: not worth a call
BIG_WORK = 100_000


@cache
def _malloc_trim() -> Any:
    """glibc's malloc_trim, or None (musl and others lack it). Looked up on first big work, and by the
    soname first: `ctypes.util.find_library` runs `ldconfig -p` in a subprocess (milliseconds, at every
    import of the engine before)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        try:
            libc = ctypes.CDLL("libc.so.6")
        except OSError:
            libc = ctypes.CDLL(ctypes.util.find_library("c"))
        trim = libc.malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_freed_memory(size: int) -> bool:
    """After work on `size` facts or atoms: return the heap's free pages to the OS (glibc), if the work
    was big. True if it ran."""
    if size < BIG_WORK:
        return False
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
