"""`tracelab sql`: a read-only SQL query on a run (live or sealed), or one of the saved queries; on several
runs (or a folder of runs) every view has a first column `run` and a saved query runs on each run
(tracelab.store.several; docs/store.md, "Several runs").

Table output shows at most DEFAULT_TABLE_ROWS rows unless --limit says otherwise (a note on stderr says
how to get everything); CSV, JSON and Parquet stream the whole result batch by batch."""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.commands._output import DEFAULT_TABLE_ROWS, arrow_rows, write_rows, write_stream
from tracelab.errors import UserError, store_errors
from tracelab.store.kind import can_read
from tracelab.store.queries import get_query, list_queries
from tracelab.store.reader import arrow_stream, fetch_rows, open_run, query_readonly, retrying
from tracelab.store.several import SeveralRunsConnection, each_run_stream, expand_runs, run_names

# a result as the table format prints it: column names, which are numbers, the rows
Rows = tuple[list[str], list[bool], list[tuple[Any, ...]]]


def _params(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        name, eq, value = item.partition("=")
        if not eq:
            raise UserError(f"cannot read --param {item!r}; write NAME=VALUE")
        out[name.strip()] = utf8_text(value.strip(), f"--param {name.strip()}")
    return out


def utf8_text(text: str, what: str) -> str:
    """An argument as text DuckDB can take: bytes that are not UTF-8 reach Python as lone surrogates."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as e:
        raw = text.encode("utf-8", "surrogateescape")
        offset = len(text[:e.start].encode("utf-8", "surrogateescape"))
        raise UserError(f"{what} is not UTF-8 text: byte 0x{raw[offset]:02x} at offset {offset}") from None
    return text


def print_saved_queries() -> None:
    for q in list_queries():
        print(f"{q.name}: {q.description}{' (game runs only)' if q.needs_board else ''}")
        for p in q.params:
            print(f"    {p.name} ({p.type}, default {p.default!r}){': ' + p.help if p.help else ''}")


def _runs_and_query(args: argparse.Namespace) -> tuple[list[str], str | None]:
    """The runs named, and the SQL (the last word) unless a saved query (--query NAME) was asked for."""
    words = list(args.words)
    if args.saved is not None:
        if words and any(c.isspace() for c in words[-1]) and not Path(words[-1]).exists():
            raise UserError("give either a SQL query or --query NAME (see --list)")
        return words, None
    if len(words) < 2:
        raise UserError("give a run and a SQL query, or --query NAME (see --list)")
    return words[:-1], words[-1]


def _statement(args: argparse.Namespace, query: str | None) -> tuple[str, dict | None, str | None]:
    """The SQL, its parameters, and why it needs a game run (a saved query about games), if it does."""
    if args.saved is not None:
        saved = get_query(args.saved)
        return saved.sql, saved.bind(_params(args.param)), saved.needs and (saved.needs, saved.needs_board)
    if args.param:
        raise UserError("--param only applies to saved queries (--query NAME)")
    return utf8_text(query, "the SQL query"), None, None


def run(args: argparse.Namespace) -> int:
    if args.list:
        print_saved_queries()
        return 0
    with store_errors(), ctrl_c_stops_queries():
        runs, query = _runs_and_query(args)
        if not runs:
            raise UserError("give a run and a SQL query, or --query NAME (see --list)")
        sql, params, needs = _statement(args, query)
        paths, folder = expand_runs(runs)
        if len(paths) == 1 and not folder:
            _query_one_run(args, runs[0], sql, params, needs)
        else:
            _query_several_runs(args, paths, sql, params, needs)
    return 0


def _query_one_run(args: argparse.Namespace, run: str, sql: str, params: dict | None,
                   needs: tuple[str, str] | None) -> None:
    con = open_run(run)
    if needs is not None and not can_read(con, needs[0]):
        any_run = ", ".join(q.name for q in list_queries() if not q.needs_board)
        lacks = "is not a run of games" if needs[0] == "games" else "has no board"
        raise UserError(f"saved query {args.saved} reads games ({needs[1]}), and {run} {lacks} (a reasoning "
                        f"run); these read any run: {any_run}")
    if args.format == "table":
        _write_table_output(args, lambda limit: retrying(lambda: _rows(con, sql, params, limit, args.offset)))
    else:
        schema, batches = retrying(lambda: arrow_stream(query_readonly(con, sql, params),
                                                        args.limit, args.offset))
        write_stream(schema, batches, args.format, args.output)


def _rows(con: Any, sql: str, params: dict | None, limit: int | None, offset: int) -> Rows:
    """The query's rows [offset, offset+limit) as the table format prints them (no pyarrow)."""
    result = fetch_rows(query_readonly(con, sql, params), limit, offset)
    return result.names, result.numeric, result.rows


def _query_several_runs(args: argparse.Namespace, paths: list, sql: str, params: dict | None,
                        needs: tuple[str, str] | None) -> None:
    """The SQL on the union of the runs' views; a saved query on each run in turn (its rows prefixed by
    the run's name)."""
    con = SeveralRunsConnection(paths, run_names(paths))

    def stream(limit: int | None):
        if args.saved is not None:
            return each_run_stream(con, sql, params, limit, args.offset, needs)
        return arrow_stream(query_readonly(con, sql, params), limit, args.offset)

    if args.format == "table" and args.saved is None:
        _write_table_output(args, lambda limit: retrying(lambda: _rows(con, sql, params, limit, args.offset)))
    elif args.format == "table":
        def rows(limit: int | None) -> Rows:
            import pyarrow as pa  # deferred: only a saved query's stream printed as a table needs it
            schema, batches = stream(limit)
            return arrow_rows(pa.Table.from_batches(list(batches), schema=schema))
        _write_table_output(args, lambda limit: retrying(lambda: rows(limit)))
    else:
        schema, batches = retrying(lambda: stream(args.limit))
        write_stream(schema, batches, args.format, args.output)


def _write_table_output(args: argparse.Namespace, fetch: Callable[[int | None], Rows]) -> None:
    """At most DEFAULT_TABLE_ROWS rows unless --limit says otherwise, with a note when rows were left."""
    limit = DEFAULT_TABLE_ROWS + 1 if args.limit is None else args.limit
    names, numeric, rows = fetch(limit)
    cut = args.limit is None and len(rows) > DEFAULT_TABLE_ROWS
    write_rows(names, numeric, rows[:DEFAULT_TABLE_ROWS] if cut else rows, args.output)
    if cut:
        print(f"note: showing the first {DEFAULT_TABLE_ROWS} rows; --limit N shows more, and "
              "--format csv|json|parquet [-o FILE] writes every row", file=sys.stderr)
