"""The end of a play recorded into a run (`tracelab play`, `tracelab play --env`): a failure closes the run
as "failed"; Ctrl-C or SIGTERM closes it as "interrupted" and ends the command with one line saying what
the run keeps (tracelab.cli.main prints a KeyboardInterrupt's message). And the closing hints' reads of
the run written (`read_for_hints`), which never fail the command."""
from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from tracelab.engine.errors import is_interrupt

# deferred: tracelab.store (DuckDB), when a run is read: reason imports this module and prints a reasoning without
# the store

T = TypeVar("T")


def read_for_hints(run_dir: Path, read: Callable[[Any], T]) -> T | None:
    """`read(con)` on the run just written, for the "what to open" hints printed after it; None if the
    run cannot be opened or the read fails (a big run past the query memory, say): the command did its
    job, and a hint is not worth failing it. Hints read the raw tables they need, not the joined views."""
    from tracelab.store import open_run
    try:
        con = open_run(run_dir)
    except Exception:  # whatever the store or DuckDB raise: the run is written, the hint is optional
        return None
    try:
        return read(con)
    except Exception:
        return None
    finally:
        con.close()


@contextmanager
def recording_into(writer: Any, run_dir: Path) -> Iterator[None]:
    """`with recording_into(writer, run_dir):` the play; the writer is the run's TraceWriter (the env may
    have closed it already, with its own status)."""
    try:
        yield
    except BaseException as e:
        if not is_interrupt(e):
            if not writer.closed:
                writer.close(status="failed")
            raise
        # Ctrl-C, or SIGTERM (the writer's handler exits)
        if not writer.closed:
            writer.close(status="interrupted")  # flushes what was played
        kept = f"{run_dir} keeps {ended_episodes(run_dir)} finished episode(s) and the trace so far"
        if isinstance(e, SystemExit):
            print(f"tracelab: terminated: {kept}", file=sys.stderr)
            raise
        raise KeyboardInterrupt(kept) from None


def ended_episodes(run_dir: Path) -> int:
    """How many episodes of the run have ended."""
    from tracelab.store import open_run

    con = open_run(run_dir)
    try:
        return int(con.execute("SELECT count(*) FROM episodes WHERE ended").fetchall()[0][0])
    finally:
        con.close()
