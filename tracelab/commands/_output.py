"""Shared by the commands that print: the terminal's escaping of everything a command writes to stdout
and stderr (`escaped_output`), the --format/--output/--limit options, writing an Arrow table as an
aligned text table, CSV, JSON or Parquet."""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import sys
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, TextIO

from tracelab.commands._args import non_negative_int
from tracelab.engine.terminal_text import printable
from tracelab.errors import UserError

if TYPE_CHECKING:  # imported where used, so that `tracelab --help` stays fast
    import pyarrow as pa

# deferred: tracelab.store.table_files (DuckDB) and pyarrow, when a table is written: cli.py and the command table
# import this module for escaped_output and the format options

FORMATS = ("table", "csv", "json", "parquet")


class EscapingStream:
    """A text stream that writes to `raw` with every control character but newline, tab (and CRLF) escaped
    (engine.terminal_text.printable): a run's strings (its command, rule names, atoms, outcomes) reach
    the terminal as text, never as escape sequences. Everything else is the raw stream's."""

    def __init__(self, raw: TextIO) -> None:
        self.raw = raw

    def write(self, text: str) -> int:
        # CSV ends its lines with \r\n: kept as a pair (a lone \r, which rewrites a line, is escaped)
        self.raw.write("\r\n".join(printable(part, keep="\n\t") for part in text.split("\r\n")))
        return len(text)

    def writelines(self, lines: Iterable[str]) -> None:
        for line in lines:
            self.write(line)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.raw, name)


def raw_stream(stream: TextIO) -> TextIO:
    """The stream under an EscapingStream: for output that draws with escape sequences of its own
    (the progress bars), from our own strings."""
    return stream.raw if isinstance(stream, EscapingStream) else stream


@contextmanager
def escaped_output() -> Iterator[None]:
    """Inside: everything printed to stdout and stderr goes through an EscapingStream. Output written
    to a file (--output) is data and is written as it is."""
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = EscapingStream(sys.stdout), EscapingStream(sys.stderr)  # type: ignore[assignment]
    try:
        yield
    finally:
        sys.stdout, sys.stderr = saved


def add_format_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--format", choices=FORMATS, default="table", help="output format (default: table)")
    p.add_argument("--output", "-o", help="write to this file (required for parquet)")


def add_paging_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--limit", type=non_negative_int, help="at most this many rows")
    p.add_argument("--offset", type=non_negative_int, default=0, help="skip this many rows first")


def _json_value(v: Any) -> Any:
    if isinstance(v, (_dt.datetime, _dt.date)):
        return v.isoformat()
    if isinstance(v, float) and math.isnan(v):
        return None
    return v


def write_table(table: "pa.Table", fmt: str, output: str | None = None, out: TextIO | None = None) -> None:
    """Write `table` in `fmt` to `output` (a path) or to `out` (default stdout)."""
    from tracelab.store.table_files import python_rows, write_csv, write_parquet

    if fmt == "parquet":
        if not output:
            raise UserError("--format parquet needs --output FILE")
        write_parquet(table.schema, table.to_batches(), output)
        return
    if output:
        with open(output, "w", newline="") as f:
            write_table(table, fmt, None, f)
        return
    out = out or sys.stdout
    if fmt == "csv":
        write_csv(table.schema, table.to_batches(), out)
        return
    if fmt == "table":
        write_rows(*arrow_rows(table), out=out)
    elif fmt == "json":
        rows = python_rows(table)
        json.dump([{k: _json_value(v) for k, v in r.items()} for r in rows], out, indent=1, default=str)
        out.write("\n")
    else:
        raise UserError(f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")


def arrow_rows(table: "pa.Table") -> tuple[list[str], list[bool], list[tuple[Any, ...]]]:
    """An Arrow table as write_rows takes it: its column names, which are numbers, its rows."""
    import pyarrow as pa

    from tracelab.store.table_files import column_values
    names = table.column_names
    columns = [column_values(table.column(i), name) for i, name in enumerate(names)]
    return (names, [pa.types.is_integer(t) or pa.types.is_floating(t) for t in table.schema.types],
            list(zip(*columns)))


def write_rows(names: Sequence[str], numeric: Sequence[bool], rows: Sequence[Sequence[Any]],
               output: str | None = None, out: TextIO | None = None) -> None:
    """Rows as an aligned text table (numbers right-aligned), then their count, to `output` (a path) or
    to `out` (default stdout): the table format, from Python values (DuckDB's rows need no pyarrow)."""
    from tracelab.store.table_files import cell_text
    if output:
        with open(output, "w", newline="") as f:
            write_rows(names, numeric, rows, None, f)
        return
    out = out or sys.stdout
    cells = [[cell_text(v) for v in r] for r in rows]
    widths = [max([len(n), *(len(c[i]) for c in cells)]) for i, n in enumerate(names)]
    fmt_row = lambda vals: "  ".join(  # noqa: E731
        v.rjust(w) if num else v.ljust(w) for v, w, num in zip(vals, widths, numeric)).rstrip()
    out.write(fmt_row(names) + "\n")
    out.write("  ".join("-" * w for w in widths) + "\n")
    for c in cells:
        out.write(fmt_row(c) + "\n")
    out.write(f"({len(rows)} row{'s' if len(rows) != 1 else ''})\n")


DEFAULT_TABLE_ROWS = 1000  # rows a table-format result shows unless --limit says otherwise


def _rows(batches: "Iterable[pa.RecordBatch]") -> "Iterator[dict[str, Any]]":
    from tracelab.store.table_files import python_rows

    for batch in batches:
        yield from python_rows(batch)


def write_stream(schema: "pa.Schema", batches: "Iterable[pa.RecordBatch]", fmt: str,
                 output: str | None = None, out: TextIO | None = None) -> int:
    """Write record batches as CSV, JSON or Parquet as they come (one batch in memory at a time); returns
    the number of rows. Table format needs every row for its widths: use write_table."""
    from tracelab.store.table_files import write_csv, write_parquet

    if fmt == "parquet":
        if not output:
            raise UserError("--format parquet needs --output FILE")
        return write_parquet(schema, batches, output)
    if fmt not in ("csv", "json"):
        raise UserError(f"format {fmt!r} does not stream; choose csv, json or parquet")
    if output:
        with open(output, "w", newline="") as f:
            return write_stream(schema, batches, fmt, None, f)
    out = out or sys.stdout
    n = 0
    if fmt == "csv":
        return write_csv(schema, batches, out)
    out.write("[")
    for r in _rows(batches):
        # one object per line: readable, and several times faster than indenting every value
        out.write(("\n" if n == 0 else ",\n") + json.dumps({k: _json_value(v) for k, v in r.items()},
                                                           default=str))
        n += 1
    out.write("]\n" if n == 0 else "\n]\n")
    return n

