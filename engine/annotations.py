"""Annotation functions: a rule head's bound computed from the bounds of the body atoms that counted
(docs/language.md, "Annotation functions").

A function takes three float64 arrays of equal length, one entry per counted atom: `lower`, `upper` and
`weights` (the weight of the atom's clause, 1 unless the rule gives `{weights=...}`), and returns
`(lower, upper)`. Built-ins are computed inside the compiled kernel (engine/kernel.py, `_agg_builtin`);
the plain-Python versions here are the specification the reference evaluator runs. User functions are
registered by name (`register_annotation`) and called from Python while the kernel waits, so adding one
never recompiles the kernel.
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .program import PREDICATE_RE  # function names are written like predicates

AnnotationFunction = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[float, float]]



def average(lower: np.ndarray, upper: np.ndarray, weights: np.ndarray) -> tuple[float, float] | None:
    """[mean of the lowers, mean of the uppers]."""
    n = len(lower)
    return _sum(lower) / n, _sum(upper) / n


def weighted_average(lower: np.ndarray, upper: np.ndarray, weights: np.ndarray) -> tuple[float, float] | None:
    """[Σ w·l / Σ w, Σ w·u / Σ w]; no bound (the rule does not fire) when Σ w = 0."""
    sw = _sum(weights)
    if sw == 0.0:
        return None
    return _sum([w * x for w, x in zip(weights, lower)]) / sw, _sum([w * x for w, x in zip(weights, upper)]) / sw


def minimum(lower: np.ndarray, upper: np.ndarray, weights: np.ndarray) -> tuple[float, float] | None:
    """[min of the lowers, min of the uppers]."""
    return float(min(lower)), float(min(upper))


def maximum(lower: np.ndarray, upper: np.ndarray, weights: np.ndarray) -> tuple[float, float] | None:
    """[max of the lowers, max of the uppers]."""
    return float(max(lower)), float(max(upper))


def average_lower(lower: np.ndarray, upper: np.ndarray, weights: np.ndarray) -> tuple[float, float] | None:
    """[mean of the lowers, max of the uppers] (PyReason's average_lower)."""
    return _sum(lower) / len(lower), float(max(upper))


def _sum(xs) -> float:
    """Left-to-right float sum: the kernel adds in the same order, so both give the same bits."""
    acc = 0.0
    for x in xs:
        acc += float(x)
    return acc


# the built-ins by name (their kernel codes: engine/aggregate_tables.py, BUILTIN_CODES)
BUILTINS: dict[str, Callable[..., tuple[float, float] | None]] = {
    "average": average,
    "weighted_average": weighted_average,
    "min": minimum,
    "max": maximum,
    "average_lower": average_lower,
}

_user: dict[str, AnnotationFunction] = {}


def register_annotation(name: str, fn: AnnotationFunction) -> float:
    """Make `fn` usable as the annotation function `name` in rule heads parsed from now on
    (`risk(X):name <-1 ...`). `fn(lower, upper, weights) -> (lower, upper)` on float64 arrays; a numba
    `njit` function is compiled here for that signature, so the first firing pays nothing. Nothing of the
    engine is recompiled. Returns the seconds registration took."""
    start = time.perf_counter()
    if not PREDICATE_RE.fullmatch(name):
        raise ValueError(f"annotation function name {name!r}: it must start with a lower-case letter and "
                         "contain letters, digits and '_'")
    if name in BUILTINS:
        raise ValueError(f"{name!r} is a built-in annotation function and cannot be replaced")
    if not callable(fn):
        raise TypeError(f"annotation function {name!r} must be callable, got {type(fn).__name__}")
    if hasattr(fn, "compile") and hasattr(fn, "py_func"):  # a numba dispatcher: compile its one signature
        fn.compile("(float64[::1], float64[::1], float64[::1])")
    _user[name] = fn
    return time.perf_counter() - start


def unregister_annotation(name: str) -> None:
    """Forget a user function (engines built with it keep their own reference)."""
    _user.pop(name, None)


def is_known(name: str) -> bool:
    return name in BUILTINS or name in _user


def lookup(name: str) -> Callable[..., tuple[float, float] | None]:
    """The Python function of a built-in or registered name (KeyError if neither)."""
    if name in BUILTINS:
        return BUILTINS[name]
    return _user[name]


def call_user(name: str, fn: AnnotationFunction, rule: str, lower: np.ndarray, upper: np.ndarray,
              weights: np.ndarray) -> tuple[float, float]:
    """Call a user function and check its answer: a bound with 0 <= lower <= upper <= 1."""
    res = fn(np.ascontiguousarray(lower, np.float64), np.ascontiguousarray(upper, np.float64),
             np.ascontiguousarray(weights, np.float64))
    try:
        lo, up = (float(res[0]), float(res[1]))
    except (TypeError, IndexError, ValueError):
        raise ValueError(f"annotation function {name!r} (rule {rule}) returned {res!r}, not a (lower, upper) "
                         "pair") from None
    if not (0.0 <= lo <= up <= 1.0):
        raise ValueError(f"annotation function {name!r} (rule {rule}) returned [{lo:g},{up:g}]: a bound needs "
                         "0 <= lower <= upper <= 1")
    return lo, up
