"""What numba's disk cache holds for a compiled function: whether its first call will compile (tens of
seconds for the step kernel) or load machine code (milliseconds), and where the cache lives.

Reads numba's own cache index of a dispatcher (numba 0.68: `Dispatcher._cache`, its `_cache_file` and
`_cache_path`), which is private: when it changes, the answers are None ("cannot tell"), never an error.
"""
from __future__ import annotations

import hashlib
import inspect
from types import ModuleType
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


def stamp_with_sources(dispatcher: Any, modules: tuple[ModuleType, ...]) -> bytes:
    """Make `dispatcher`'s disk cache stale when any of `modules` changes: numba stamps only the file
    defining the function, not the callees it compiles in from other modules (the engine's kernel, a
    game's read-back). Uses numba's cache file object (numba 0.68: Cache._cache_file._source_stamp,
    compared on every load). Returns the stamp: a hash of the modules' sources."""
    digest = hashlib.sha256()
    for m in modules:
        digest.update(inspect.getsource(m).encode())
        digest.update(b"\0")
    stamp = digest.digest()
    cache_file = dispatcher._cache._cache_file
    if not hasattr(cache_file, "_source_stamp"):
        raise ImportError(f"numba's cache no longer has _source_stamp: {dispatcher.__name__} cannot key its cache")
    cache_file._source_stamp = stamp
    return stamp
