"""`tracelab runs`: the run catalog (status live from the writer's lock, command, scenario, episodes,
change rows, size, start time) of the runs in some directories (default ./runs and sample_runs/)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.commands._output import write_rows, write_table
from tracelab.errors import store_errors
from tracelab.store.catalog import DEFAULT_ROOTS, ROW_COLUMNS, catalog_table, list_runs


def run(args: argparse.Namespace) -> int:
    roots = args.dirs or list(DEFAULT_ROOTS)
    with store_errors(), ctrl_c_stops_queries():
        for d in args.dirs:
            if not Path(d).exists():
                raise FileNotFoundError(f"no such directory or run: {d!r}")
            if not Path(d).is_dir():  # a run is a directory too; a file or FIFO is neither
                raise NotADirectoryError(f"not a directory or run: {d!r}")
        runs = list_runs(roots)
        rows = [r.as_row() for r in runs]
        if args.format == "table":
            for r in rows:
                r["command"] = _short(r["command"])
            write_rows(list(ROW_COLUMNS), list(ROW_COLUMNS.values()), [tuple(r.values()) for r in rows], args.output)
        else:
            write_table(catalog_table(rows), args.format, args.output)
    for r in runs:  # after the block: a Ctrl-C that broke a read ends the command there, with no notes
        if r.error:
            print(f"note: {r.path}: {r.error}", file=sys.stderr)
    return 0


def _short(command: str, width: int = 48) -> str:
    """The command cut to `width` characters."""
    return command if len(command) <= width else command[: width - 1] + "…"
