"""Calling a compiled function's machine code without numba's per-call dispatch, for a hot call whose first
argument is a large record that stays the same over many calls (the kernel's StepState).

Numba's dispatcher types every argument on every call: for a tuple of arrays it fingerprints each array
(a StepState of 59: most of an `Engine.step()` call from Python on a small program; docs/benchmarks.md,
"Engine.step from Python"). DirectCall types the record once, finds the compiled overload for it and the
other arguments, and then calls that overload's entry point, which only unboxes. The other (small)
arguments are fingerprinted on every call, as numba would, and anything not seen at resolution goes through
the dispatcher (which compiles or raises as usual) and is resolved again, so no call reaches machine code
compiled for other types. Reads numba 0.68's `Dispatcher.overloads[sig].entry_point`; when that is missing,
every call goes through the dispatcher.
"""
from __future__ import annotations

from typing import Any

from numba import typeof
from numba._dispatcher import compute_fingerprint


class DirectCall:
    """dispatcher(record, *args) for a fixed `record`, through the overload's entry point once resolved."""

    def __init__(self, dispatcher: Any, record: tuple[Any, ...]) -> None:
        self.dispatcher = dispatcher
        self.record = record
        self._record_type: Any = None  # typed on the first resolution (~1 ms for a StepState)
        self._key: tuple[bytes, ...] | None = None  # the fingerprints of the args the entry was resolved for
        self._entry: Any = None

    @property
    def resolved(self) -> bool:
        """Whether the last call's argument types have an entry point (calls of those types skip dispatch)."""
        return self._key is not None

    def __call__(self, *args: Any) -> Any:
        key = tuple(map(compute_fingerprint, args))
        if key == self._key:
            return self._entry(self.record, *args)
        result = self.dispatcher(self.record, *args)  # compiles for new types, or raises as numba does
        self._resolve(key, args)
        return result

    def _resolve(self, key: tuple[bytes, ...], args: tuple[Any, ...]) -> None:
        try:
            if self._record_type is None:
                self._record_type = typeof(self.record)
            sig = (self._record_type, *(self.dispatcher.typeof_pyval(a) for a in args))
            entry = self.dispatcher.overloads[sig].entry_point
        except (AttributeError, KeyError, ValueError):  # numba's layout changed: stay with the dispatcher
            return
        self._key, self._entry = key, entry
