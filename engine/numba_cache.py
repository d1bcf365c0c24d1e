"""What numba's disk cache holds for a compiled function: whether its first call will compile (tens of
seconds for the step kernel) or load machine code (milliseconds), and where the cache lives.

Reads numba's own cache index of a dispatcher (numba 0.68: `Dispatcher._cache`, its `_cache_file` and
`_cache_path`), which is private: when it changes, the answers are None ("cannot tell"), never an error.
"""
from __future__ import annotations

from typing import Any


def is_cached(dispatcher: Any) -> bool | None:
    """True when `dispatcher` is compiled in this process or numba's disk cache has a current index for it
    (numba's own staleness check: an index whose source stamp differs loads as empty), False when its
    first call compiles, None when it cannot tell."""
    try:
        if dispatcher.signatures:
            return True
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:  # numba's cache layout is private
        return None


def all_cached(dispatchers: tuple[Any, ...]) -> bool | None:
    """True when every one is cached (is_cached), False when one is not, None when one cannot tell."""
    answers = [is_cached(d) for d in dispatchers]
    if False in answers:
        return False
    return None if None in answers else True


def cache_folder(dispatcher: Any) -> str | None:
    """The folder numba caches `dispatcher`'s machine code in (its locator's choice: next to the source,
    under $NUMBA_CACHE_DIR, or numba's user-wide folder), or None when it cannot tell."""
    try:
        return str(dispatcher._cache._cache_path)
    except Exception:
        return None
