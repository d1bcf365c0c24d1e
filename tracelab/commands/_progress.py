"""Progress on long work, for any command: a bar with rate and ETA (`progress`), a spinner for work of
unknown length (`working`), and the first-run compile notice (`compiling_engine`).

They draw on stderr, and only when stdout and stderr are terminals: piped or redirected output stays
clean. rich is imported only when something is drawn, so that `tracelab --help` stays fast.

    with progress("playing", total=2000, unit="episodes") as bar:
        for ...:
            bar.advance(1)
            bar.set_fields(wins=w, **{"steps/s": rate})
"""
from __future__ import annotations

import importlib
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from typing import Any

from tracelab.commands._output import raw_stream

# deferred: rich, on a terminal only; the engine's cache and grounding watch (numba) when an engine is built: seal
# and a small printed reasoning need none of them

# the numba kernels whose first call compiles the engine (the counting kernel serves every program, the
# lanes kernel batches of 64 worlds or more) and the trace taker of a recorder with an episode clock (a declared
# env's recording; not `reason`: a notice about it would show on every reasoning). A declared world's own step
# says its compile itself (tracelab/envs/declared/world.py)
_ENGINE_KERNELS = (("tracelab.engine.kernel", "step_worlds"),)
_LOCAL_TRACE_KERNELS = (("tracelab.engine.trace_take", "take_local_columns"),)
_LANES_KERNELS = (("tracelab.engine.lanes", "step_lanes"),)


def on_terminal() -> bool:
    """Draw progress only for a person watching: stdout and stderr both terminals."""
    return sys.stdout.isatty() and sys.stderr.isatty()


class Progress:
    """What the body of `progress(...)` gets: advance the count, show live figures. Quiet when not on a
    terminal (then it only counts)."""

    def __init__(self, bar: Any = None, task: Any = None) -> None:
        self._bar, self._task = bar, task
        self.completed = 0
        self.figures: dict[str, Any] = {}

    def advance(self, n: int = 1) -> None:
        self.completed += n
        if self._bar is not None:
            self._bar.advance(self._task, n)

    def set_fields(self, **figures: Any) -> None:
        """Live figures shown after the bar, e.g. set_fields(loss=0.31, win_rate=0.62)."""
        self.figures.update(figures)
        if self._bar is not None:
            self._bar.update(self._task, figures=_figures_text(self.figures))


def _figures_text(figures: dict[str, Any]) -> str:
    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:,.0f}" if abs(v) >= 100 else f"{v:.3g}"
        return f"{v:,}" if isinstance(v, int) else str(v)
    return "  ".join(f"{k} {fmt(v)}" for k, v in figures.items())


@contextmanager
def progress(description: str, total: int | None, unit: str | None = "steps") -> Iterator[Progress]:
    """A progress bar with count, rate (unless `unit` is None) and ETA on a terminal; a counter that
    draws nothing elsewhere."""
    if not on_terminal():
        yield Progress()
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        ProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )
    from rich.progress import Progress as RichProgress
    from rich.text import Text

    class RateColumn(ProgressColumn):
        def render(self, task: Any) -> Text:
            rate = "…" if task.speed is None else f"{task.speed:,.1f}"
            return Text(f"{rate} {unit}/s", style="progress.data.speed")

    columns = [TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
               *([RateColumn()] if unit else []), TimeElapsedColumn(), TextColumn("eta"),
               TimeRemainingColumn(), TextColumn("{task.fields[figures]}")]
    with RichProgress(*columns, console=Console(file=raw_stream(sys.stderr)), transient=True) as bar:
        task = bar.add_task(description, total=total, figures="")
        yield Progress(bar, task)


@contextmanager
def working(description: str, refresh_per_second: float = 10) -> Iterator[Progress]:
    """A spinner with the elapsed time and live figures (set_fields) for work whose length is not known
    beforehand (refreshing less often where its thread must not disturb a measurement)."""
    if not on_terminal():
        yield Progress()
        return
    from rich.console import Console
    from rich.progress import Progress as RichProgress
    from rich.progress import SpinnerColumn, TextColumn, TimeElapsedColumn
    with RichProgress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(),
                      TextColumn("{task.fields[figures]}"), console=Console(file=raw_stream(sys.stderr)),
                      transient=True, refresh_per_second=refresh_per_second) as bar:
        yield Progress(bar, bar.add_task(description, total=None, figures=""))


def _kernels(pairs: tuple[tuple[str, str], ...]) -> tuple[Any, ...] | None:
    try:
        return tuple(getattr(importlib.import_module(module), name) for module, name in pairs)
    except (ImportError, AttributeError):
        return None


def _cold(pairs: tuple[tuple[str, str], ...]) -> bool | None:
    """True when some of these kernels must compile, False when all are loaded or cached (or run as Python:
    nothing compiles), None: unknown."""
    from tracelab.engine.numba_cache import all_cached
    from tracelab.engine.numba_python import running_as_python
    if running_as_python():
        return False
    kernels = _kernels(pairs)
    cached = all_cached(kernels) if kernels is not None else None
    return None if cached is None else not cached


def _engine_kernels(lanes: bool, local_trace: bool) -> tuple[tuple[str, str], ...]:
    return _ENGINE_KERNELS + (_LANES_KERNELS if lanes else ()) + (_LOCAL_TRACE_KERNELS if local_trace else ())


def engine_cache_is_cold(lanes: bool = False, local_trace: bool = False) -> bool | None:
    """True when the engine's compiled kernels (with `lanes` the lanes kernel's too, with `local_trace`
    the trace taker's) are neither loaded nor in numba's disk cache (the first run compiles them), False
    when they are, None when it cannot tell. Reads numba's cache index of each entry point (a few ms)."""
    return _cold(_engine_kernels(lanes, local_trace))


def compile_notice(lanes: bool = False, local_trace: bool = False, phase: str = "play") -> str | None:
    """What a first run compiles, in words (None when nothing, or unknown), with what `tracelab bench
    first-run` measured for `phase` (tracelab/first_run_figures.py)."""
    if not _cold(_engine_kernels(lanes, local_trace)):
        return None
    what = "the rule engine's step kernel"
    kernels = _kernels(_ENGINE_KERNELS[:1])
    from tracelab.engine.numba_cache import cache_folder
    folder = cache_folder(kernels[0]) if kernels else None
    cached = f"; cached for the next runs in {folder}" if folder else ""
    from tracelab.first_run_figures import measured
    return f"compiling the engine ({measured(phase)}): {what}{cached}"


class Warmup(Progress):
    """What `compiling_engine` yields: a spinner's figures, and afterwards the time spent and whether
    the kernels were compiled (True, False, or None: unknown)."""
    seconds: float = 0.0
    compiled: bool | None = None


@contextmanager
def compiling_engine(lanes: bool = False, busy: str | None = None, local_trace: bool = False,
                     phase: str | None = "play") -> Iterator[Warmup]:
    """Around the engine's build and first step (with `lanes`: a batch that takes the lanes kernel): when
    the kernels must be compiled, say so while it happens (a spinner on a terminal, one line on stderr
    otherwise); when they are cached, show `busy` (if given) as a spinner on a terminal. The spinner
    counts the groundings found (a big build's work). `phase`: the first run `tracelab bench first-run`
    measured for the notice's figure; None: the body's library code says its own notice (a declared
    world: tracelab/envs/declared/world.py)."""
    from tracelab.engine.grounding import watch_grounding
    cold = engine_cache_is_cold(lanes, local_trace)
    notice = compile_notice(lanes, local_trace, phase) if cold and phase else None
    t0 = time.perf_counter()
    if notice and not on_terminal():  # one line, once: on a terminal the spinner says it
        print(f"tracelab: {notice}", file=sys.stderr, flush=True)
    if notice:
        description: str | None = f"{notice}…"
    else:
        description = "compiling the engine (first run only)…" if cold is not False else busy
    spinner = working(description) if description else nullcontext(Progress())
    with spinner as shown:
        warm = Warmup(shown._bar, shown._task)
        warm.compiled = cold
        try:
            def grounded(n: int) -> None:
                warm.set_fields(groundings=n, **{"groundings/s": n / max(time.perf_counter() - t0, 1e-9)})

            with watch_grounding(grounded):
                yield warm
        finally:
            warm.seconds = time.perf_counter() - t0
