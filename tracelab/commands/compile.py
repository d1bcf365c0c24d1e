"""`tracelab compile RULES...`: compile a rule program's own kernel ahead (kernel="compiled",
docs/engine-api.md), so that `--kernel compiled` and `auto` find it in the cache. A run that asks for
`--kernel compiled` before this compiles it the same way (tracelab.engine.compile_job) in the background."""
from __future__ import annotations

import argparse
import sys
from contextlib import ExitStack

from tracelab.commands._progress import working
from tracelab.engine import load_program
from tracelab.engine.backend_compiled import unsupported
from tracelab.engine.compile_job import CompileRefused, compile_program
from tracelab.errors import UserError


def _say(text: str) -> None:
    print(f"tracelab compile: {text}", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    program = load_program(*args.program)
    names = " ".join(args.program)
    if why := unsupported(program):
        raise UserError(f"cannot compile {names}: {why} (such programs run on the counting kernel)")
    with ExitStack() as spinning:
        def announce(entry, cached: bool) -> None:  # noqa: ANN001
            _say(f"{names}: {len(program.rules)} rules, kernel {entry.key} in {entry.dir.parent}")
            what = "loading the cached kernel" if cached else \
                "generating and compiling the kernel with numba (a minute or so; once per program and library version)"
            _say(f"{what}...")
            spinning.enter_context(working(f"{what}…"))

        try:
            outcome = compile_program(program, announce)
        except CompileRefused as e:
            raise UserError(f"cannot compile {names}: {e}") from e
    _say(f"{'loaded (already cached)' if outcome.cached else 'compiled and cached'} in {outcome.wall_s:.1f} s "
         f"({outcome.cpu_s:.1f} s of CPU): {outcome.entry.dir}")
    print(outcome.entry.dir)
    return 0
