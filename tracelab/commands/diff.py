"""`tracelab diff`: where two episodes of a run first diverge (trace and actions)."""
from __future__ import annotations

import argparse
import json

from tracelab.commands._output import fail, store_errors


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("diff", help="the first divergence of two episodes of a run")
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    p.add_argument("a", type=int, help="episode")
    p.add_argument("b", type=int, help="the other episode")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tracelab.store.diff import first_divergence, render_divergence
    from tracelab.store.reader import open_run, retrying
    try:
        con = open_run(args.run)
        d = retrying(lambda: first_divergence(con, args.a, args.b))
    except store_errors() as e:
        return fail(e)
    print(json.dumps(d.to_dict(), indent=1, default=str) if args.json else render_divergence(d))
    return 0
