"""numba's kernels run as their Python source, for a process that must not wait for their first compile.

A cold `tracelab play` would spend a minute of CPU compiling the engine's kernels before its first step
(docs/benchmarks.md, "Issue 40: the first play of a fresh install"). Every kernel is written in the Python
that numba compiles, over numpy arrays, so it also runs as plain Python: slower per step (33 steps a
second on GridWar's advanced scenario), the same results, no compile. `PythonKernels.swap()` puts each
numba dispatcher's Python function (`py_func`) where tracelab's loaded modules hold the dispatcher (module
globals, and static methods of their classes); a kernel's calls of other kernels go through its module's
globals, so they run as Python too. `restore()` puts the dispatchers back (they load numba's cache, once a
background process has filled it).

What this cannot reach: a dispatcher held elsewhere (in a container, a closure, an instance) still
compiles when called. A numba-only construct (an @overload's stand-in) needs a Python body that does the
same: envs/declared/fused.py's _new_buffers.
"""
from __future__ import annotations

import sys
from typing import Any

from numba.core.dispatcher import Dispatcher

_swaps = 0  # swaps and restores so far: a caller that binds compiled structures binds again when it changes


def generation() -> int:
    """A number that changes whenever the kernels go from compiled to Python or back."""
    return _swaps


def running_as_python() -> bool:
    """Whether the kernels run as Python now (a swap not yet restored)."""
    return _swaps % 2 == 1


class PythonKernels:
    """The kernels of the loaded modules under `package`, swapped to Python and back (see the module)."""

    def __init__(self, package: str = "tracelab") -> None:
        self.package = package
        self._swapped: list[tuple[Any, str, Any]] = []  # (module or class, name, what it held)

    def swap(self) -> int:
        """Run every kernel as Python from now on; the number of references replaced."""
        global _swaps
        if self._swapped:
            return len(self._swapped)
        prefix = self.package + "."
        for name, module in list(sys.modules.items()):
            if module is None or not (name == self.package or name.startswith(prefix)):
                continue
            for key, value in list(vars(module).items()):
                if isinstance(value, Dispatcher):
                    self._replace(module, key, value, value.py_func)
                elif isinstance(value, type) and value.__module__ == name:
                    self._swap_class(value)
        _swaps += 1
        return len(self._swapped)

    def restore(self) -> None:
        """The compiled kernels again (numba loads each from its cache, or compiles it, at its next call)."""
        global _swaps
        if not self._swapped:
            return
        for owner, key, value in reversed(self._swapped):
            setattr(owner, key, value)
        self._swapped = []
        _swaps += 1

    def _swap_class(self, cls: type) -> None:
        for key, value in list(vars(cls).items()):
            if isinstance(value, staticmethod) and isinstance(value.__func__, Dispatcher):
                self._replace(cls, key, value, staticmethod(value.__func__.py_func))

    def _replace(self, owner: Any, key: str, old: Any, new: Any) -> None:
        self._swapped.append((owner, key, old))
        setattr(owner, key, new)
