"""Curves of several runs for the Training view: each run's metrics read through its own RunSource (re-read
while it is live, like the view's own run), and, per metric, the runs' mean with a min–max band.

Runs log at their own steps (the same steps when their --log-every / --eval-every agree, as for seeds of
one setting). They are matched at every step any of them logged, each run counting its latest value at
or before that step, over the steps every run has reached (from the last first step to the first last
step): where the runs share their steps these are exactly the values at that step."""
from __future__ import annotations

import bisect
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from tracelab.viewers.tui.source import LiveReads, RunSource

Curve = tuple[list[float], list[float]]   # steps, values (NaN for a missing value)


@dataclass
class RunCurves:
    """One run's metrics by name, as last read."""
    source: RunSource
    label: str
    live_reads: LiveReads = field(init=False)
    seen: tuple[int, int] | None = None     # (rows, last step) when last read
    curves: dict[str, Curve] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.live_reads = LiveReads(self.source)

    def read(self) -> bool:
        """Re-read the run's metrics if they grew (a worker thread); True if they changed."""
        if not self.live_reads.due:
            return False
        with self.live_reads.read() as last:
            r = self.source.rows("SELECT count(*) AS n, coalesce(max(step), -1) AS last FROM metrics")[0]
            mark = (int(r["n"]), int(r["last"]))
            if mark == self.seen and not last:
                return False
            rows = self.source.rows("SELECT name, step, value FROM metrics ORDER BY name, step, time, value")
        curves: dict[str, Curve] = defaultdict(lambda: ([], []))
        for row in rows:
            xs, ys = curves[row["name"]]
            xs.append(row["step"])
            ys.append(float("nan") if row["value"] is None else row["value"])
        self.curves, self.seen = dict(curves), mark
        return True


def run_labels(paths: list[Path]) -> list[str]:
    """Short names for runs: their directory names, or their paths where two names are the same."""
    names = [p.name for p in paths]
    return [n if names.count(n) == 1 else str(p) for n, p in zip(names, paths)]


def _latest(xs: list[float], ys: list[float], step: float) -> float:
    """The curve's value at its last point at or before `step`."""
    i = bisect.bisect_right(xs, step) - 1
    return ys[i] if i >= 0 else float("nan")


def mean_band(curves: list[Curve]) -> tuple[list[float], list[float], list[float], list[float]] | None:
    """(steps, mean, min, max) over the runs' curves of one metric, matched as the module says; None when
    fewer than two runs have it or their steps do not overlap. NaN values are left out of a step's
    figures (all NaN: NaN)."""
    present = [(xs, ys) for xs, ys in curves if xs]
    if len(present) < 2:
        return None
    start, end = max(xs[0] for xs, _ in present), min(xs[-1] for xs, _ in present)
    steps = sorted({x for xs, _ in present for x in xs if start <= x <= end})
    out: tuple[list[float], list[float], list[float], list[float]] = (steps, [], [], [])
    for step in steps:
        values = [v for v in (_latest(xs, ys, step) for xs, ys in present) if not math.isnan(v)]
        mean = sum(values) / len(values) if values else float("nan")
        out[1].append(mean)
        out[2].append(min(values) if values else float("nan"))
        out[3].append(max(values) if values else float("nan"))
    return out if steps else None
