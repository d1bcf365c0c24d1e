"""`tracelab seal`: compact a finished run's Parquet parts into one read-only DuckDB file."""
from __future__ import annotations

import argparse

from tracelab.commands._progress import progress
from tracelab.errors import store_errors
from tracelab.store.schema import TABLES
from tracelab.store.seal import seal_run


def run(args: argparse.Namespace) -> int:
    with store_errors(), progress("sealing", total=len(TABLES), unit=None) as bar:
        path = seal_run(args.run, keep_parts=args.keep_parts,
                        on_table=lambda name: (bar.advance(1), bar.set_fields(copied=name)))
    print(path)
    return 0
