"""`tracelab compile RULES...`: compile a rule program's own kernel ahead (kernel="compiled",
docs/engine-api.md), so that `--kernel compiled` and `auto` find it in the cache."""
from __future__ import annotations

import argparse
import sys
import time

from tracelab.errors import UserError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compile", help="compile a rule program to its own kernel and cache it on disk")
    p.add_argument("program", nargs="+", help="rule files (merged into one program, as `reason` merges them)")
    p.set_defaults(func=run)


def _say(text: str) -> None:
    print(f"tracelab compile: {text}", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    from tracelab.commands._progress import working
    from tracelab.engine import Engine, FixpointError, InconsistencyError, load_program
    from tracelab.engine.backend_compiled import GenerationError, cache_entry, unsupported

    program = load_program(*args.program)
    names = " ".join(args.program)
    if why := unsupported(program):
        raise UserError(f"cannot compile {names}: {why} (such programs run on the counting kernel)")
    t0 = time.perf_counter()
    probe = Engine(program, kernel="counting", trace=True)  # the program's tables, no compile
    entry = cache_entry(probe)
    cached = entry.ready
    try:
        entry.load()  # writes the generated module (cheap); numba compiles at the first step
    except GenerationError as e:
        raise UserError(f"cannot compile {names}: {e}") from e
    _say(f"{names}: {len(program.rules)} rules, kernel {entry.key} in {entry.dir.parent}")
    what = "loading the cached kernel" if cached else "generating and compiling the kernel with numba " \
                                                     "(a minute or so; once per program and library version)"
    _say(f"{what}...")
    with working(f"{what}…"):
        engine = Engine(program, kernel="compiled", trace=True)
        try:
            engine.step()  # the first step compiles the kernel (or loads it) and caches it
        except (InconsistencyError, FixpointError):
            pass  # the program's own facts: compiling does not depend on how its first step ends
    took = time.perf_counter() - t0
    if engine.kernel != "compiled" or not entry.ready:
        raise UserError(f"cannot compile {names}: {engine.kernel_notice or 'the kernel was not cached'}")
    _say(f"{'loaded (already cached)' if cached else 'compiled and cached'} in {took:.1f} s: {entry.dir}")
    print(entry.dir)
    return 0
