"""The trace buffer's rows as new columns in one compiled call, with `t` made local to each world's
episode (Engine.take_trace(t_start=..., episode=...); a simulator's episode clock).

Its own module, calling nothing elsewhere: numba's disk cache does not notice changes to callees in
other modules. The layout is kernel.py's trace buffer (int32 [rows, 8]: world, t, pass_no, atom,
cause_kind, cause_id, grounding, n_sources; float64 [rows, 4]). Few arrays are returned because numba
boxes each (its cost: docs/benchmarks.md, "Figures behind the code")."""
from __future__ import annotations

import numpy as np
from numba import njit

# the int32 block's rows, by trace column (cause_kind and n_sources have their own dtypes)
INT32_COLUMNS = ("world", "t", "pass_no", "atom", "cause_id", "grounding")
_FROM_BUFFER = (0, 1, 2, 3, 5, 6)  # their columns in the int32 trace buffer


@njit(cache=True)
def take_local_columns(tri, trf, n, t_start, episode):  # noqa: ANN001, ANN201
    """Rows 0..n-1 of the trace buffers as new arrays: int32 [6, n] (INT32_COLUMNS, with t - t_start[world]),
    cause_kind int8 [n], n_sources int16 [n], float64 [4, n] (old_lower, old_upper, new_lower, new_upper)
    and episode[world] int64 [n]."""
    ints = np.empty((6, n), np.int32)
    for c in range(6):
        src = _FROM_BUFFER[c]
        for r in range(n):
            ints[c, r] = tri[r, src]
    for r in range(n):
        ints[1, r] = tri[r, 1] - t_start[tri[r, 0]]
    kind = np.empty(n, np.int8)
    nsrc = np.empty(n, np.int16)
    ep = np.empty(n, np.int64)
    for r in range(n):
        kind[r] = tri[r, 4]
        nsrc[r] = tri[r, 7]
        ep[r] = episode[tri[r, 0]]
    floats = np.empty((4, n), np.float64)
    for c in range(4):
        for r in range(n):
            floats[c, r] = trf[r, c]
    return ints, kind, nsrc, floats, ep
