"""The statistics the experiment reports use: binomial intervals, a two-proportion test, bootstrap
intervals of a difference of means, and the spread over seeds."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95% Wilson interval of a proportion (sane at 0 and n, unlike the normal one)."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    # it holds p; rounding can put an end a hair inside p at 0 or n (a negative error bar in plots)
    return max(0.0, min(p, mid - half)), min(1.0, max(p, mid + half))


def two_proportion_test(k1: int, n1: int, k2: int, n2: int) -> tuple[float, float]:
    """(z, two-sided p-value) of H0: both proportions are equal (pooled normal approximation)."""
    pooled = (k1 + k2) / (n1 + n2)
    se = math.sqrt(pooled * (1 - pooled) * (1 / n1 + 1 / n2))
    if se == 0:
        return 0.0, 1.0  # both all wins or all non-wins: no evidence of a difference
    z = (k1 / n1 - k2 / n2) / se
    return z, math.erfc(abs(z) / math.sqrt(2))


def bootstrap_diff_ci(a: Sequence[float], b: Sequence[float], rounds: int = 2000,
                      seed: int = 0) -> tuple[float, float]:
    """95% percentile-bootstrap interval of mean(a) - mean(b), a and b resampled independently."""
    rng = np.random.default_rng(seed)
    x, y = np.asarray(a, float), np.asarray(b, float)
    da = x[rng.integers(0, len(x), (rounds, len(x)))].mean(1)
    db = y[rng.integers(0, len(y), (rounds, len(y)))].mean(1)
    lo, hi = np.percentile(da - db, [2.5, 97.5])
    return float(lo), float(hi)


def spread(values: Sequence[float]) -> dict[str, float]:
    """Mean, min, max and a 95% t-interval of the mean over seeds (NaN with one seed)."""
    v = np.asarray(values, float)
    out = {"n": len(v), "mean": float(v.mean()), "min": float(v.min()), "max": float(v.max())}
    if len(v) > 1:
        t = {2: 12.706, 3: 4.303, 4: 3.182, 5: 2.776, 6: 2.571, 7: 2.447, 8: 2.365, 9: 2.306,
             10: 2.262}.get(len(v), 1.96)  # t(0.975, n-1) by n seeds
        half = t * v.std(ddof=1) / math.sqrt(len(v))
        out.update(ci_low=out["mean"] - half, ci_high=out["mean"] + half)
    else:
        out.update(ci_low=math.nan, ci_high=math.nan)
    return out
