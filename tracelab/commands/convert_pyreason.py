"""`tracelab convert-pyreason`: write a PyReason program (its rule, fact and GraphML files) as the
equivalent tracelab program, which `tracelab reason` reads back (docs/pyreason.md)."""
from __future__ import annotations

import argparse
import sys

from tracelab.errors import UserError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("convert-pyreason", help="write PyReason rules/facts/graph as a tracelab program")
    p.add_argument("rules", nargs="+", help="PyReason rule files (.txt one rule a line, .csv, .json)")
    p.add_argument("--facts", action="append", default=[], help="PyReason fact files (.csv, .json)")
    p.add_argument("--graph", help="a GraphML graph read with PyReason's mapping; its facts are written into "
                                   "the program as static facts")
    p.add_argument("--persistent", action="store_true",
                   help="PyReason's persistent=True (default: PyReason's non-persistent timesteps)")
    p.add_argument("-o", "--output", help="the tracelab rule file to write (default: standard output)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # deferred: loads numba; every command is imported to build the CLI's parser
    from tracelab.pyreason import load_pyreason

    translated = load_pyreason(args.rules, args.facts, args.graph, persistent=args.persistent, embed_graph=True)
    if args.output is None:
        sys.stdout.write(translated.text)
        return 0
    try:
        with open(args.output, "w", encoding="utf-8") as f:
            f.write(translated.text)
    except OSError as e:
        raise UserError(f"cannot write {args.output}: {e.strerror}") from None
    print(f"wrote {args.output}", file=sys.stderr)
    return 0
