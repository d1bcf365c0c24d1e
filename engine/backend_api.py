"""What a kernel backend may read and write of the Engine that owns it.

The backends (backend_counting, backend_lanes) are constructed by the Engine (core.py) and work on its
program tables, trace buffers, statistics and error slots. They type against this protocol instead of
importing core.py, so the engine's modules import in one direction: core -> backends -> kernels."""
from __future__ import annotations

from typing import Protocol

import numpy as np

from .program import Rule


class EngineTables(Protocol):
    """The Engine's fields a backend uses (engine/core.py documents each where it sets it)."""
    n_worlds: int
    rules: list[Rule]
    trace_on: np.ndarray      # bool [W]: worlds whose changes are traced
    _cfg: np.ndarray          # int64 [N_CFG]: the kernel's configuration slots
    _err: np.ndarray          # int64 [N_ERR]: the kernel's error report
    _stats: np.ndarray        # int64 [W, N_STATS]
    _tri: np.ndarray          # int32 trace rows (growable)
    _trf: np.ndarray          # float64 trace bounds (growable)
    _tr_n: np.ndarray         # int64 [1]: trace rows written
    _settable: np.ndarray     # bool [atoms]: atoms that some rule or fact may set
    _fact_i: np.ndarray
    _fact_f: np.ndarray
    _fact_v: np.ndarray
    _fact_order: np.ndarray
    _rule_i: np.ndarray
    _rule_f: np.ndarray
    _rule_v: np.ndarray
    _ext_codes: np.ndarray    # int8: crisp codes of this step's external rows (lanes)

    def _grow_trace(self, need: int) -> None: ...
