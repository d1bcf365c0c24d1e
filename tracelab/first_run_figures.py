"""What a first compile cost when measured: the figures the compile notices quote, so that a notice says
what a fresh install measured, not a guess. `tracelab bench first-run --write-figures` writes them into
first_run_figures.json beside this module (each phase from empty caches: play, reason-large, spec-env,
spec-vector-env, train; docs/benchmarks.md), with the date and the machine's load."""
from __future__ import annotations

import json
import logging
from collections.abc import Iterable
from functools import cache
from pathlib import Path
from typing import Any

FIGURES = Path(__file__).resolve().parent / "first_run_figures.json"


@cache
def _table() -> dict[str, Any]:
    try:
        return json.loads(FIGURES.read_text())
    except (OSError, ValueError):
        return {}


def measured(phase: str) -> str:
    """`first run only; a fresh install measured 63 s of CPU, 372 s wall at load 15 on 2 cores, 2026-11-28`
    for a phase the bench timed (CPU first: the wall time is the measuring machine's load's as much as
    the compile's), `first run only` for one it did not."""
    table = _table()
    figure = table.get("figures", {}).get(phase)
    if not isinstance(figure, dict) or not {"wall_s", "cpu_s"} <= figure.keys():
        return "first run only"
    when = str(table.get("measured", "?")).split(" ")[0]
    try:
        load = f" at load {table['load'][0][0]:.0f} on {table['cores']} cores"
    except (KeyError, IndexError, TypeError, ValueError):
        load = ""
    return (f"first run only; a fresh install measured {figure['cpu_s']:.0f} s of CPU, "
            f"{figure['wall_s']:.0f} s wall{load}, {when}")


_said: set[str] = set()


def say_first_compile(log: logging.Logger, phase: str, what: str, cached: Iterable[bool | None]) -> None:
    """Log (info) one line, once per process and phase, when one of `cached` is False: the kernels that
    `what` names compile at the first step (the CLI shows it on stderr: commands/_notices.py)."""
    if phase in _said or False not in list(cached):
        return
    _said.add(phase)
    log.info("compiling %s (%s)", what, measured(phase))
