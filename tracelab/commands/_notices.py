"""What the library reports, shown on the command line: the library (engine, store, train) prints nothing and
logs its notices to the `tracelab` loggers (tracelab.engine.notices); while a command runs,
`showing_library_notices` writes them to stderr, one line each, as the engine wrote them itself before:

    tracelab: notice: kernel 'compiled' not used: ...         (a warning: something asked for is not done)
    tracelab: the compiled kernel is ready (...); switched...  (info: what happens in the background)

A command that reports nothing (every reading command) does not load `logging`: it is imported by the
first library module that makes a logger (library_logger), which the block's writer then hears from.
"""
from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager

from tracelab.engine.notices import showing_notices


def _stderr_line(is_warning: bool, message: str) -> None:
    """One line on the current sys.stderr (looked up at each notice: tests swap it)."""
    print(f"tracelab: {'notice: ' if is_warning else ''}{message}", file=sys.stderr, flush=True)


@contextmanager
def showing_library_notices() -> Iterator[None]:
    """While the block runs, the library's info and warnings (its `tracelab` loggers) go to stderr."""
    with showing_notices(_stderr_line):
        yield


def say_running_compiles() -> None:
    """At the end of a run: one line per background compile still running (it goes on without the run)."""
    from tracelab.engine.compile_background import running  # when used: `tracelab --help` stays fast
    for job in running():
        print(f"tracelab: the compiled kernel is still being built in the background (pid {job.pid}); the "
              f"next run takes it from the cache (--kernel compiled or auto)", file=sys.stderr, flush=True)
