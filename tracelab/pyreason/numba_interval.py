"""PyReason's annotation functions as tracelab annotation functions.

PyReason calls a user's function `f(annotations, weights)` from its compiled reasoner: `annotations` a
numba typed list, per body clause, of the typed list of the bounds (intervals with `.lower` and `.upper`)
of the atoms that clause counted, `weights` a typed list of one float per clause; it returns
(lower, upper). tracelab's engine calls a registered function with three arrays, one entry per counted
atom: lowers, uppers and the weight of the atom's clause (engine/annotations.py). So a PyReason rule
naming `f` is translated with weights that number its clauses (1, 2, ...), and `adapter()` regroups the
atoms by clause from them, builds PyReason's typed lists and calls `f` with the rule's own weights.

`NumbaInterval` is the interval the function reads (a numba structref: `.lower`, `.upper` in and out of
compiled code); `closed(l, u)` makes one, as PyReason's `interval.closed` does. Its constructor is
compiled at the first use in a process (numba does not cache a structref's constructor), which is why
this module is imported only by programs that use it."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numba
import numpy as np
from numba.core import types
from numba.experimental import structref


@structref.register
class NumbaIntervalType(types.StructRef):
    def preprocess_fields(self, fields: Any) -> tuple[tuple[str, Any], ...]:
        return tuple((name, types.unliteral(t)) for name, t in fields)


class NumbaInterval(structref.StructRefProxy):
    """A closed interval [lower, upper] that compiled functions read (`.lower`, `.upper`)."""

    def __new__(cls, lower: float, upper: float) -> "NumbaInterval":
        return structref.StructRefProxy.__new__(cls, float(lower), float(upper))

    @property
    def lower(self) -> float:
        return _lower(self)

    @property
    def upper(self) -> float:
        return _upper(self)

    def __repr__(self) -> str:
        return f"[{self.lower},{self.upper}]"


@numba.njit(cache=True)
def _lower(iv: Any) -> float:
    return iv.lower


@numba.njit(cache=True)
def _upper(iv: Any) -> float:
    return iv.upper


structref.define_proxy(NumbaInterval, NumbaIntervalType, ["lower", "upper"])


def adapter(fn: Callable[..., Any], weights: Sequence[float]) -> Callable[[np.ndarray, np.ndarray, np.ndarray],
                                                                          tuple[float, float]]:
    """A tracelab annotation function calling PyReason's `fn` for a rule whose translation numbers its
    clauses in the weights (clause k has weight k + 1) and whose own weights are `weights`."""
    n = len(weights)
    typed_weights = numba.typed.List([float(w) for w in weights])

    def call(lower: np.ndarray, upper: np.ndarray, clause_numbers: np.ndarray) -> tuple[float, float]:
        per_clause: list[list[NumbaInterval]] = [[] for _ in range(n)]
        for lo, up, k in zip(lower.tolist(), upper.tolist(), clause_numbers.tolist()):
            per_clause[int(round(k)) - 1].append(NumbaInterval(lo, up))
        annotations = numba.typed.List()
        for bounds in per_clause:
            clause = numba.typed.List.empty_list(NumbaIntervalType(fields=(("lower", types.float64),
                                                                          ("upper", types.float64))))
            for b in bounds:
                clause.append(b)
            annotations.append(clause)
        lo, up = fn(annotations, typed_weights)
        return float(lo), float(up)

    return call
