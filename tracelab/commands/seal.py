"""`tracelab seal`: compact a finished run's Parquet parts into one read-only DuckDB file."""
from __future__ import annotations

import argparse

from tracelab.commands._progress import progress
from tracelab.errors import store_errors


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("seal", help="compact a finished run into <run>/run.duckdb")
    p.add_argument("run", help="run directory or run name under runs/")
    p.add_argument("--keep-parts", action="store_true", help="keep the Parquet parts afterwards")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # deferred: loads DuckDB; every command is imported to build the CLI's parser
    from tracelab.store.schema import TABLES
    from tracelab.store.seal import seal_run
    with store_errors(), progress("sealing", total=len(TABLES), unit=None) as bar:
        path = seal_run(args.run, keep_parts=args.keep_parts,
                        on_table=lambda name: (bar.advance(1), bar.set_fields(copied=name)))
    print(path)
    return 0
