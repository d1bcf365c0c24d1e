"""Compiling a program's own kernel (the compiled backend, docs/engine-api.md): ahead with `tracelab compile`,
or in a background process while a run goes on on the counting kernel.

Both take the same path, `compile_program`: build the Engine with kernel="compiled" and step it once (its
first step compiles the generated module with numba, whose `cache=True` writes the machine code beside it).
A compile holds an exclusive lock on its cache entry (CacheEntry.locked), so two runs asking for the same
kernel at once compile it once: the second waits, then finds it cached. Every file of an entry is written to
a temporary name and then linked (kernel.py, never replaced) or renamed (numba's index and data,
ready.json), so a reader never loads half of one; compile_cache.py checks an entry before it is used.

The background process is `python -m tracelab.engine.compile_job KEY`, started by compile_background.py
(which the Engine uses; this module imports the Engine, that one does not): it reads the program pickled
by `start` from its stdin (a pipe from the parent, so no pickle file sits anywhere another process could
replace: unpickling runs code), compiles it, and prints one JSON line (the times) as the last line of its
log, `<entry>/compile.<pid>.<ns>.log` (removed once the kernel is ready; kept when it fails). It runs in
its own session, so a Ctrl-C of the run does not stop it: a run that ends first leaves it to finish, and
the next run finds the kernel via kernel="auto". Its prints are that log, not a library's output.
"""
from __future__ import annotations

import dataclasses
import json
import pickle
import sys
import time
from collections.abc import Callable

from .compile_cache import CacheEntry
from .core import Engine
from .errors import FixpointError, InconsistencyError
from .program import Program


@dataclasses.dataclass
class CompileOutcome:
    entry: CacheEntry
    cached: bool      # the kernel was in the cache already (loaded, not compiled)
    wall_s: float     # building the engine and its first (compiling) step
    cpu_s: float      # the same in this process's CPU time


class CompileRefused(Exception):
    """The compiled backend does not take this program (the message says why)."""


def compile_program(program: Program, announce: Callable[[CacheEntry, bool], None] | None = None,
                    expect_key: str | None = None) -> CompileOutcome:
    """Compile `program`'s kernel into the cache (or find it there), holding its entry's lock while the
    first step compiles. `announce(entry, cached)` is called once the lock is held, before the minute a
    compile takes. `expect_key`: refuse unless the kernel's cache key is this one."""
    t0, c0 = time.perf_counter(), time.process_time()
    engine = Engine(program, kernel="compiled", trace=True)  # writes the generated module, compiles nothing
    if engine.kernel != "compiled":
        raise CompileRefused(engine.kernel_notice or "the compiled backend did not take the program")
    entry = engine._state.entry
    if expect_key is not None and entry.key != expect_key:  # another interpreter or library version
        raise CompileRefused(f"this process computes kernel {entry.key}, the run asked for {expect_key}")
    with entry.locked():
        cached = entry.ready  # after waiting for another compile of the same kernel, it usually is
        if announce is not None:
            announce(entry, cached)
        try:
            engine.step()  # compiles the kernel (or loads numba's cache); CompiledState marks it ready
        except (InconsistencyError, FixpointError):
            pass  # the program's own facts: compiling does not depend on how its first step ends
    if not entry.ready:
        raise CompileRefused(f"the kernel was not cached in {entry.dir}")
    return CompileOutcome(entry, cached, time.perf_counter() - t0, time.process_time() - c0)


def main(argv: list[str]) -> int:
    """The child: compile the program pickled on stdin by `start` (its parent); the last line of output
    is the outcome as JSON."""
    key = argv[0]
    program = pickle.loads(sys.stdin.buffer.read())
    print(f"compiling {len(program.rules)} rules (kernel {key})", flush=True)
    try:
        outcome = compile_program(program, expect_key=key)
    except CompileRefused as e:
        print(f"not compiled: {e}", flush=True)
        return 1
    print(json.dumps({"cached": outcome.cached, "wall_s": round(outcome.wall_s, 3),
                      "cpu_s": round(outcome.cpu_s, 3)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
