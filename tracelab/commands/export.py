"""`tracelab export RUN --tensorboard DIR`: a run's training metrics as TensorBoard event files in
DIR/<run name>/ (the optional `tensorboard` extra; tracelab.train.tensorboard). The run is read through
the store's sandboxed reader and written nowhere else; the store stays the record."""
from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.commands.compare import without_metrics
from tracelab.errors import UserError, store_errors
from tracelab.store.kind import is_game_run
from tracelab.store.reader import open_run, query_readonly, resolve_run, retrying
from tracelab.train.tensorboard import EVENTS_GLOB, TensorBoardSink, export_metrics, run_log_dir


def run_name(run: Path) -> str:
    """The name a run's curves get: its directory's name (for a run's own run.duckdb, the run's)."""
    run = run.resolve()
    if run.is_dir():
        return run.name
    return run.parent.name if run.name == "run.duckdb" else run.stem


def run(args: argparse.Namespace) -> int:
    with store_errors(), ctrl_c_stops_queries():
        path = resolve_run(args.run)
        log_dir = run_log_dir(Path(args.tensorboard), run_name(path))
        con = open_run(path)
        try:
            (status, command, metrics), = retrying(lambda: query_readonly(
                con, "SELECT status, command, (SELECT count(*) FROM metrics) FROM run").fetchall())
            if not metrics:
                raise UserError(f"{without_metrics(args.run, is_game_run(con), command)}: export --tensorboard "
                                f"converts a training run's metrics")
            counts = _export(con, log_dir)
        finally:
            con.close()
    if status == "running":
        print(f"note: {args.run} is still training: exported its metrics up to now", file=sys.stderr)
    print(f"wrote {counts['scalars']:,} scalars ({counts['names']} metric names, steps {counts['first_step']:,}"
          f"-{counts['last_step']:,}) to {log_dir}/")
    print(f"  tensorboard --logdir {shlex.quote(args.tensorboard)}")
    return 0


def _export(con: Any, log_dir: Path) -> dict[str, int]:
    """The run's metrics into a new event file in log_dir; an export that fails (or Ctrl-C) removes it, so
    that a second try does not find half a run there."""
    sink = TensorBoardSink(log_dir)
    try:
        counts = export_metrics(con, sink)
    except BaseException:
        sink.close()
        for made in set(log_dir.glob(EVENTS_GLOB)):
            made.unlink()
        raise
    sink.close()
    return counts
