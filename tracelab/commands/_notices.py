"""What the library reports, shown on the command line: the library (engine, store, train) prints nothing and
logs its notices to the `tracelab` loggers; while a command runs, `showing_library_notices` writes them to
stderr, one line each, as the engine wrote them itself before:

    tracelab: notice: kernel 'compiled' not used: ...         (a warning: something asked for is not done)
    tracelab: the compiled kernel is ready (...); switched...  (info: what happens in the background)
"""
from __future__ import annotations

import logging
import sys
from collections.abc import Iterator
from contextlib import contextmanager

LIBRARY_LOGGER = "tracelab"


class _StderrLines(logging.Handler):
    """One line on the current sys.stderr per record (looked up at each record: tests swap it)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            kind = "notice: " if record.levelno >= logging.WARNING else ""
            print(f"tracelab: {kind}{record.getMessage()}", file=sys.stderr, flush=True)
        except Exception:  # logging's contract: a handler never raises into the code that logged
            self.handleError(record)


@contextmanager
def showing_library_notices() -> Iterator[None]:
    """While the block runs, the library's info and warnings (its `tracelab` loggers) go to stderr."""
    logger = logging.getLogger(LIBRARY_LOGGER)
    handler, level = _StderrLines(logging.INFO), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


def say_running_compiles() -> None:
    """At the end of a run: one line per background compile still running (it goes on without the run)."""
    from tracelab.engine.compile_background import running  # when used: `tracelab --help` stays fast
    for job in running():
        print(f"tracelab: the compiled kernel is still being built in the background (pid {job.pid}); the "
              f"next run takes it from the cache (--kernel compiled or auto)", file=sys.stderr, flush=True)
