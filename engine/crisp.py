"""The crisp bounds as value codes: [0,1] V_U, [1,1] V_T, [0,0] V_F. The Engine reads every program's
bounds as codes (a program is crisp when all are) to choose its kernel; the lanes kernel (lanes.py) runs on
them. Here, without numba, so that a reasoning on the counting kernel does not import the lanes kernel
(docs/benchmarks/history.md, "PyReason's API").

The codes are written out again in lanes.py, not imported there: numba freezes globals into its cached
machine code and does not notice a change in another module; tests/test_lanes.py checks both agree."""
from __future__ import annotations

import numpy as np

V_U, V_T, V_F = 0, 1, 2  # [0,1], [1,1], [0,0]


def crisp_codes(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The lanes value code of each bound ([0,1] V_U, [1,1] V_T, [0,0] V_F), -1 where it is not crisp."""
    lower, upper = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    code = np.full(lower.shape, -1, np.int8)
    code[(lower == 0.0) & (upper == 1.0)] = V_U
    code[(lower == 1.0) & (upper == 1.0)] = V_T
    code[(lower == 0.0) & (upper == 0.0)] = V_F
    return code
