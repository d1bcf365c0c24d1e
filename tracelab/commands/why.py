"""`tracelab why`: the proof tree of an atom's bound at a time in an episode, read from the stored trace."""
from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING

from tracelab.commands._output import fail, store_errors

if TYPE_CHECKING:
    import duckdb


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("why", help="why an atom had its bound at a time: the rules, facts and actions behind it")
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    p.add_argument("atom", help="a ground atom, e.g. 'atLoc(red-agent-1,16)'")
    p.add_argument("--episode", "-e", type=int, required=True)
    p.add_argument("--at", type=int, help="timestep (default: the episode's last)")
    p.add_argument("--depth", type=int, default=6, help="how many rule firings deep to explain (default 6)")
    p.add_argument("--json", action="store_true", help="the tree as JSON")
    p.set_defaults(func=run)


def last_t(con: "duckdb.DuckDBPyConnection", episode: int) -> int:
    """The episode's last timestep: its recorded t_end, else its last trace row's."""
    row = con.execute("SELECT coalesce((SELECT max(t_end) FROM raw.episode_end WHERE episode = $e), "
                      "(SELECT max(t) FROM raw.changes WHERE episode = $e))", {"e": episode}).fetchone()
    if row[0] is None:
        raise KeyError(f"episode {episode} has no trace rows")
    return int(row[0])


def run(args: argparse.Namespace) -> int:
    from tracelab.store.reader import open_run, retrying
    from tracelab.store.why import explain, render_why
    try:
        con = open_run(args.run)
        at = last_t(con, args.episode) if args.at is None else args.at
        tree = retrying(lambda: explain(con, args.episode, args.atom, at, depth=args.depth))
    except store_errors() as e:
        return fail(e)
    if args.json:
        print(json.dumps({"episode": args.episode, "at": at, "tree": tree.to_dict()}, indent=1))
    else:
        print(render_why(tree, at))
    return 0
