"""Shared by the commands that print query results: the --format/--output/--limit options, writing an
Arrow table as an aligned text table, CSV, JSON or Parquet, and turning store errors into messages."""
from __future__ import annotations

import argparse
import csv
import datetime as _dt
import json
import math
import sys
from typing import TYPE_CHECKING, Any, TextIO

if TYPE_CHECKING:  # imported where used, so that `tracelab --help` stays fast
    import pyarrow as pa

FORMATS = ("table", "csv", "json", "parquet")


def add_format_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--format", choices=FORMATS, default="table", help="output format (default: table)")
    p.add_argument("--output", "-o", help="write to this file (required for parquet)")


def add_paging_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--limit", type=int, help="at most this many rows")
    p.add_argument("--offset", type=int, default=0, help="skip this many rows first")


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:g}"
    if isinstance(v, (list, tuple)):
        return "[" + ",".join(_cell(x) for x in v) + "]"
    return str(v)


def _json_value(v: Any) -> Any:
    if isinstance(v, (_dt.datetime, _dt.date)):
        return v.isoformat()
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def write_table(table: "pa.Table", fmt: str, output: str | None = None, out: TextIO | None = None) -> None:
    """Write `table` in `fmt` to `output` (a path) or to `out` (default stdout)."""
    if fmt == "parquet":
        if not output:
            raise ValueError("--format parquet needs --output FILE")
        import pyarrow.parquet as pq
        pq.write_table(table, output, compression="zstd")
        return
    if output:
        with open(output, "w", newline="") as f:
            write_table(table, fmt, None, f)
        return
    out = out or sys.stdout
    names = table.column_names
    rows = table.to_pylist()
    if fmt == "csv":
        w = csv.writer(out)
        w.writerow(names)
        for r in rows:
            w.writerow([_cell(r[n]) if isinstance(r[n], (list, tuple)) else r[n] for n in names])
    elif fmt == "json":
        json.dump([{k: _json_value(v) for k, v in r.items()} for r in rows], out, indent=1, default=str)
        out.write("\n")
    elif fmt == "table":
        import pyarrow as pa
        cells = [[_cell(r[n]) for n in names] for r in rows]
        widths = [max([len(n), *(len(c[i]) for c in cells)]) for i, n in enumerate(names)]
        numeric = [pa.types.is_integer(t) or pa.types.is_floating(t) for t in table.schema.types]
        fmt_row = lambda vals: "  ".join(  # noqa: E731
            v.rjust(w) if num else v.ljust(w) for v, w, num in zip(vals, widths, numeric)).rstrip()
        out.write(fmt_row(names) + "\n")
        out.write("  ".join("-" * w for w in widths) + "\n")
        for c in cells:
            out.write(fmt_row(c) + "\n")
        out.write(f"({len(rows)} row{'s' if len(rows) != 1 else ''})\n")
    else:
        raise ValueError(f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    v = int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {v}")
    return v


def fail(e: BaseException) -> int:
    """Print a store or query error as `error: ...` and return the exit status 1."""
    msg = e.args[0] if isinstance(e, KeyError) and e.args else str(e)
    print(f"error: {msg}", file=sys.stderr)
    return 1


def store_errors() -> tuple[type[BaseException], ...]:
    import duckdb
    return (KeyError, ValueError, FileNotFoundError, RuntimeError, duckdb.Error)
