"""How many rule groundings a program may make: past the limit the grounder refuses the program before
it builds the groundings (engine/grounding.py), instead of meeting the system's out-of-memory killer.

A grounding costs a few hundred bytes at its peak (its rows, the join's temporaries, the kernel's tables
built from them): `t(X,Z) <-0 n(X), n(Y), n(Z)` over 100 nodes made 1,000,000 groundings in 434 MB, and a
3 KB rule file over 400 nodes asked for 64 million, 24 GB. By default groundings may take half of the
memory this process may use; `grounding_limit(n)` (the CLI's `--max-groundings`) sets the limit for the
engines built inside it, `Engine(max_groundings=n)` for one engine.
"""
from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

BYTES_PER_GROUNDING = 512  # the measure above (434 bytes), rounded up
_MEMORY_LIMIT_FILES = ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes")
_FALLBACK_MEMORY = 4 << 30  # where the memory size cannot be read

_chosen: list[int] = []  # grounding_limit() contexts, innermost last


def usable_memory() -> int:
    """Bytes of memory this process may use: the machine's, or its container's limit if lower."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = _FALLBACK_MEMORY
    for path in _MEMORY_LIMIT_FILES:
        try:
            with open(path, encoding="ascii") as f:
                text = f.read(64).strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return total


def default_max_groundings() -> int:
    """The limit tied to the machine: half of its usable memory at BYTES_PER_GROUNDING a grounding."""
    return usable_memory() // 2 // BYTES_PER_GROUNDING


@contextmanager
def grounding_limit(n: int) -> Iterator[None]:
    """Inside: engines built without their own `max_groundings` allow `n` groundings."""
    if n < 1:
        raise ValueError(f"the grounding limit must be at least 1, got {n}")
    _chosen.append(n)
    try:
        yield
    finally:
        _chosen.pop()


def limit_in_force(max_groundings: int | None = None) -> tuple[int, str]:
    """The limit an engine applies (its own `max_groundings`, else grounding_limit()'s, else the machine's)
    and how to name where it came from in a message."""
    if max_groundings is not None:
        return max_groundings, "as given"
    if _chosen:
        return _chosen[-1], "as given"
    return default_max_groundings(), f"the default for {usable_memory() / (1 << 30):.3g} GiB of memory"
