"""`tracelab tui`: the terminal UI (tracelab.viewers.tui): runs, episodes, the trace with why-trees,
rules, a read-only SQL console and live training curves (docs/tui.md)."""
from __future__ import annotations

import argparse
from pathlib import Path

from tracelab.errors import UserError, store_errors


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tui", help="terminal UI: browse runs, traces, why-trees, rules, SQL, training curves")
    p.add_argument("paths", nargs="*", metavar="RUN|DIR",
                   help="a run to open (several runs: the first, with the others' curves overlaid in its Training "
                        "view), or directories of runs (default: runs/ and sample_runs/)")
    p.add_argument("--screenshots", metavar="DIR",
                   help="write the README's screenshots (PNG) to DIR and exit: tui-trace-why.png from the "
                        "first RUN (default sample_runs/advanced), tui-training.png from the second, a "
                        "training run (default sample_runs/base-train), tui-reasoning.png from the third, a "
                        "run without a board (default sample_runs/supply-chain) (needs rsvg-convert)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    missing = [p for p in args.paths if not Path(p).exists()]
    if missing:
        raise UserError(f"no such run or directory: {missing[0]!r}")
    if args.screenshots:
        # deferred: not needed to build the CLI's parser (`tracelab --help` imports every command)
        from tracelab.viewers.tui.screenshots import write_screenshots
        with store_errors():  # no rsvg-convert, or a run that does not open
            trace_run, training_run, reasoning_run = (Path(p) if p else None for p in (args.paths + [None] * 3)[:3])
            for path in write_screenshots(Path(args.screenshots), trace_run, training_run, reasoning_run):
                print(path)
        return 0
    # deferred: loads DuckDB, textual; every command is imported to build the CLI's parser
    from tracelab.viewers.tui.app import TracelabApp
    TracelabApp(args.paths).run()
    return 0
