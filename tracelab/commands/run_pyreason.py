"""`tracelab run-pyreason SCRIPT.py [ARGS]`: run a PyReason script as it is, `import pyreason` resolved to
tracelab's PyReason API for this run only (docs/pyreason.md, "Scripts as they are")."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run-pyreason", help="run a PyReason script unchanged on tracelab")
    p.add_argument("script", help="the PyReason script (.py)")
    p.add_argument("script_args", nargs=argparse.REMAINDER, help="the script's own arguments")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # deferred: loads numba; every command is imported to build the CLI's parser
    from tracelab.pyreason.as_pyreason import run_script

    run_script(args.script, args.script_args)
    return 0
