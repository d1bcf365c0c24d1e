"""`tracelab run-pyreason SCRIPT.py [ARGS]`: run a PyReason script as it is, `import pyreason` resolved to
tracelab's PyReason API for this run only (docs/pyreason.md, "Scripts as they are")."""
from __future__ import annotations

import argparse
from tracelab.pyreason.as_pyreason import run_script


def run(args: argparse.Namespace) -> int:
    run_script(args.script, args.script_args)
    return 0
