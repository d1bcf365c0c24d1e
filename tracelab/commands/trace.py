"""`tracelab trace`: the method's trace table for one episode (t, node/edge, label, old bound, new bound,
rule fired), filtered by time, atom, label and rule.

The table shows the episode's dynamics: the rows of static facts (tracelab.store.static_facts) are hidden,
with a note on stderr saying how many and that --static shows them; the exports (csv, json, parquet) keep
every row unless --hide-static. Where the run declares a grid (tracelab.store.coordinates), the table's
cells read `30@(6,3)`; exports keep the ids."""
from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.commands._output import write_rows, write_stream
from tracelab.errors import UserError, store_errors
from tracelab.store.coordinates import run_grid
from tracelab.store.names import check_name
from tracelab.store.reader import arrow_stream, fetch_rows, open_run, retrying
from tracelab.store.static_facts import STATIC_ROW_SQL

if TYPE_CHECKING:
    import duckdb

    from tracelab.store.coordinates import Grid
    from tracelab.store.reader import QueryRows

FULL_COLUMNS = ("t, pass_no, atom, node, label, old_lower, old_upper, new_lower, new_upper, rule, "
                "grounding, seq")


def hides_static(args: argparse.Namespace) -> bool:
    """The table hides static facts unless --static; exports keep them unless --hide-static."""
    return args.static is False or (args.static is None and args.format == "table")


def trace_where(args: argparse.Namespace) -> tuple[list[str], list[object]]:
    """The conditions of the user's filters (episode, time, atom, label, rule) and their parameters."""
    where: list[str] = ["episode = ?"]
    params: list[object] = [args.episode]
    if args.t_from is not None:
        where.append("t >= ?")
        params.append(args.t_from)
    if args.t_to is not None:
        where.append("t <= ?")
        params.append(args.t_to)
    for column, values in (("atom", args.atom), ("label", args.label), ("rule", args.rule)):
        if values:
            where.append("(" + " OR ".join(f"{column} GLOB ?" for _ in values) + ")")
            params.extend(values)
    return where, params


def trace_sql(args: argparse.Namespace) -> tuple[str, list[object]]:
    where, params = trace_where(args)
    if hides_static(args):
        where.append(f"NOT {STATIC_ROW_SQL}")
    sql = f"SELECT {FULL_COLUMNS} FROM changes WHERE {' AND '.join(where)} ORDER BY seq"
    if args.limit is not None:
        sql += f" LIMIT {int(args.limit)}"
    if args.offset:
        sql += f" OFFSET {int(args.offset)}"
    return sql, params


def check_range(args: argparse.Namespace) -> None:
    if args.t_from is not None and args.t_to is not None and args.t_from > args.t_to:
        raise UserError(f"--from {args.t_from} is after --to {args.t_to}: nothing can match")


def check_filters(con: "duckdb.DuckDBPyConnection", args: argparse.Namespace) -> None:
    """A filter that matches nothing in the run is a typo: say so, with the close names, not "(0 rows)"."""
    for kind, patterns in (("atom", args.atom), ("label", args.label), ("cause", args.rule)):
        for pattern in patterns:
            check_name(con, kind, pattern)


def run(args: argparse.Namespace) -> int:
    check_range(args)
    with store_errors(), ctrl_c_stops_queries():
        con = open_run(args.run)
        check_filters(con, args)
        if not con.execute("SELECT count(*) FROM (SELECT 1 FROM raw.changes WHERE episode = ? LIMIT 1)",
                           [args.episode]).fetchall()[0][0]:
            known = [e for (e,) in con.execute("SELECT DISTINCT episode FROM raw.changes "
                                               "ORDER BY 1 LIMIT 20").fetchall()]
            raise UserError(f"episode {args.episode} has no trace rows in {args.run} "
                            f"(episodes with rows: {known or 'none'})")
        sql, params = trace_sql(args)
        hidden = retrying(lambda: hidden_static_rows(con, args)) if hides_static(args) else 0
        if args.format == "table":
            rows = retrying(lambda: fetch_rows(con.sql(sql, params=params)))
            write_rows(PAPER_COLUMNS, [name == "t" for name in PAPER_COLUMNS], paper_rows(rows, run_grid(con)),
                       args.output)
        else:  # streamed, batch by batch
            schema, batches = retrying(lambda: arrow_stream(con.sql(sql, params=params)))
            write_stream(schema, batches, args.format, args.output)
    if hidden:
        rows = "row" if hidden == 1 else "rows"
        print(f"note: {hidden:,} {rows} of static facts hidden (atoms set by facts declared static, such as a "
              f"game's map or a graph's attributes, which never change); --static shows them", file=sys.stderr)
    return 0


def hidden_static_rows(con: "duckdb.DuckDBPyConnection", args: argparse.Namespace) -> int:
    """How many rows under the user's filters are static facts' (the ones hiding them leaves out)."""
    where, params = trace_where(args)
    sql = f"SELECT count(*) FROM changes WHERE {' AND '.join(where)} AND {STATIC_ROW_SQL}"
    return int(con.execute(sql, params).fetchall()[0][0])


def _b(lo: float, up: float) -> str:
    return f"[{lo:g},{up:g}]"


PAPER_COLUMNS = ["t", "node/edge", "label", "old", "new", "rule"]


def paper_rows(result: "QueryRows", grid: "Grid | None" = None) -> list[tuple[object, ...]]:
    """The method's columns (PAPER_COLUMNS): t, node/edge, label, old, new, rule; with a grid, cells as
    `30@(6,3)`."""
    col = {name: i for i, name in enumerate(result.names)}
    t, node, label, rule = col["t"], col["node"], col["label"], col["rule"]
    bounds = col["old_lower"], col["old_upper"], col["new_lower"], col["new_upper"]
    return [(r[t], r[node] if grid is None else grid.with_coordinates(r[node]), r[label],
             _b(r[bounds[0]], r[bounds[1]]), _b(r[bounds[2]], r[bounds[3]]), r[rule]) for r in result.rows]
