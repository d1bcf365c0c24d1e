"""numba's start-up without scipy: numba imports scipy.linalg only to learn whether BLAS is there.

The first kernel a process loads from numba's disk cache refreshes numba's target context, which imports
numba.np.arraymath, whose import asks `_check_blas()` (numba 0.68: `import scipy.linalg.cython_blas`) to
set `_HAVE_BLAS`, read only when np.correlate / np.convolve is compiled. Importing scipy.linalg costs
about 0.17 s of CPU (scipy 1.17; docs/benchmarks/history.md, "PyReason's API"), and no tracelab kernel uses BLAS.
`defer_scipy_import()` imports arraymath with that check held back and gives `_HAVE_BLAS` the same answer
when numba first reads it: scipy is imported then, by the code that needs it, not by every reasoning.

numba's internals are private: unless arraymath's source sets the flag as numba 0.68 does (the line
`_HAVE_BLAS = _check_blas()`), this does nothing.
"""
from __future__ import annotations

import importlib.util
import sys
from collections.abc import Callable

_NUMBA_BLAS_LINE = "\n_HAVE_BLAS = _check_blas()\n"


class _BlasAnswer:
    """numba's `_HAVE_BLAS`, asked of numba's own check when first read (`if not _HAVE_BLAS:`)."""

    def __init__(self, check: Callable[[], bool]) -> None:
        self._check = check
        self._answer: bool | None = None

    def __bool__(self) -> bool:
        if self._answer is None:
            self._answer = bool(self._check())
        return self._answer


def defer_scipy_import() -> bool:
    """Import numba.np.arraymath now without importing scipy.linalg; True if done. Nothing to do (False)
    when arraymath is already imported, scipy.linalg already is (nothing to save), or numba's layout is
    not the one this knows."""
    if "numba.np.arraymath" in sys.modules or "scipy.linalg" in sys.modules:
        return False
    from numba.core.compiler_lock import global_compiler_lock
    from numba.np import linalg
    ensure_blas = getattr(linalg, "ensure_blas", None)
    if ensure_blas is None or _NUMBA_BLAS_LINE not in _source("numba.np.arraymath"):
        return False

    def held_back() -> None:
        raise ImportError("scipy.linalg: asked later (tracelab.engine.numba_startup)")

    # numba compiles under this lock: no compile can call linalg.ensure_blas while it is swapped
    with global_compiler_lock:
        linalg.ensure_blas = held_back
        try:
            from numba.np import arraymath
        finally:
            linalg.ensure_blas = ensure_blas
        if getattr(arraymath, "ensure_blas", None) is held_back:
            arraymath.ensure_blas = ensure_blas  # bound by its `from numba.np.linalg import ensure_blas`
        arraymath._HAVE_BLAS = _BlasAnswer(arraymath._check_blas)
    return True


def _source(module: str) -> str:
    """A module's source text without importing it ("" when it cannot be read)."""
    try:
        spec = importlib.util.find_spec(module)
        return (spec.loader.get_source(module) or "") if spec is not None and spec.loader is not None else ""
    except (ImportError, OSError, AttributeError):
        return ""
