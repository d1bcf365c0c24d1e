"""Importing a heavy module with Python's garbage collector paused, then freezing what it made.

textual's, DuckDB's, numba's and numpy's modules make tens of thousands of objects that live until the
process exits. Collections run while they are imported find little to free, and a later one would traverse
them all: together ~15 ms of a reading command's CPU, ~0.1 s of the TUI's first screen and ~0.25 s of
PyReason's warm hello world (docs/benchmarks.md, issue 40; docs/benchmarks/history.md, "The warm hello
world, cut to what it uses"). `gc.freeze()` moves them out of every generation, so no collection (the
interpreter's at exit included) traverses them. What this gives up: an object made before the freeze that
later becomes cyclic garbage is never freed."""
from __future__ import annotations

import gc
import importlib
import sys
from types import ModuleType


def import_frozen(name: str) -> ModuleType:
    """`import name` with no collection while it loads (the collector put back as it was); the first time,
    the objects of what it loaded, and of everything loaded before, are frozen."""
    if name in sys.modules:
        return sys.modules[name]
    collecting = gc.isenabled()
    gc.disable()
    try:
        module = importlib.import_module(name)
    finally:
        if collecting:
            gc.enable()
    gc.freeze()
    return module
