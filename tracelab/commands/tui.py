"""`tracelab tui`: the terminal UI (tracelab.viewers.tui): runs, episodes, the trace with why-trees,
rules, a read-only SQL console and live training curves (docs/tui.md)."""
from __future__ import annotations

import argparse
from pathlib import Path

from tracelab.errors import UserError, store_errors
from tracelab.viewers.tui import load_app


def run(args: argparse.Namespace) -> int:
    missing = [p for p in args.paths if not Path(p).exists()]
    if missing:
        raise UserError(f"no such run or directory: {missing[0]!r}")
    if args.screenshots:
        # imported here: it drives every view (the trace, why, decision, plots), which `tracelab tui`
        # loads only when a view is first shown (issue 40: the first screen)
        from tracelab.viewers.tui.screenshots import write_screenshots
        with store_errors():  # no rsvg-convert, or a run that does not open
            trace_run, training_run, reasoning_run = (Path(p) if p else None for p in (args.paths + [None] * 3)[:3])
            for path in write_screenshots(Path(args.screenshots), trace_run, training_run, reasoning_run):
                print(path)
        return 0
    load_app()(args.paths).run()
    return 0
