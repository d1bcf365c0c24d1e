"""The end of a play recorded into a run (`tracelab play`, `tracelab play --env`): a failure closes the run
as "failed"; Ctrl-C or SIGTERM closes it as "interrupted" and ends the command with one line saying what
the run keeps (tracelab.cli.main prints a KeyboardInterrupt's message)."""
from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from tracelab.engine.errors import is_interrupt


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
    # deferred: importing tracelab.store loads DuckDB and pandas, which `tracelab --help` does not need
    from tracelab.store import open_run

    con = open_run(run_dir)
    try:
        return int(con.execute("SELECT count(*) FROM episodes WHERE ended").fetchall()[0][0])
    finally:
        con.close()
