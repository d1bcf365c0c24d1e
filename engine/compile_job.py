"""Compiling a program's own kernel (the compiled backend, docs/engine-api.md): ahead with `tracelab compile`,
or in a background process while a run goes on on the counting kernel.

Both take the same path, `compile_program`: build the Engine with kernel="compiled" and step it once (its
first step compiles the generated module with numba, whose `cache=True` writes the machine code beside it).
A compile holds an exclusive lock on its cache entry (CacheEntry.locked), so two runs asking for the same
kernel at once compile it once: the second waits, then finds it cached. Every file of an entry is written to
a temporary name and then linked (kernel.py, never replaced) or renamed (numba's index and data,
ready.json), so a reader never loads half of one; compile_cache.py checks an entry before it is used.

The background process is `python -m tracelab.engine.compile_job KEY`: it reads the program pickled by
`start` from its stdin (a pipe from the parent, so no pickle file sits anywhere another process could
replace: unpickling runs code), compiles it, and prints one JSON line (the times) as the last line of its
log, `<entry>/compile.<pid>.<ns>.log` (removed once the kernel is ready; kept when it fails). It runs in
its own session, so a Ctrl-C of the run does not stop it: a run that ends first leaves it to finish, and
the next run finds the kernel via kernel="auto".
"""
from __future__ import annotations

import dataclasses
import json
import os
import pickle
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO

from .compile_cache import CacheEntry, CacheRefused, EntryRejected
from .safe_files import create_new
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
    from .core import Engine  # core starts background compiles: import it only when compiling
    from .errors import FixpointError, InconsistencyError
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


class BackgroundCompile:
    """A compile of one cache entry in a child process (see the module's docstring)."""

    def __init__(self, entry: CacheEntry, proc: subprocess.Popen, log: Path) -> None:
        self.entry, self.proc, self.log = entry, proc, log
        self.started = time.monotonic()
        self.status = "running"  # then "ready" or "failed"
        self.wall_s: float | None = None  # from start to the end of the process, seen from this one
        self.result: dict = {}            # the child's JSON line: cached, wall_s, cpu_s
        self.why = ""                     # why it failed: the last line of its log

    @property
    def pid(self) -> int:
        return self.proc.pid

    def poll(self) -> str:
        """"running", "ready" or "failed" (a cheap check: one waitpid while it runs)."""
        if self.status == "running" and self.proc.poll() is not None:
            self._finished()
        return self.status

    def wait(self, timeout: float | None = None) -> str:
        """Block until the child ends (or `timeout` seconds pass); its status."""
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            pass
        return self.poll()

    def _finished(self) -> None:
        self.wall_s = time.monotonic() - self.started
        lines = self.log.read_text(errors="replace").splitlines() if self.log.exists() else []
        last = lines[-1] if lines else ""
        try:
            self.result = json.loads(last)
        except ValueError:
            self.result = {}
        if self.proc.returncode == 0 and self.entry.ready:
            try:
                self.entry.load()  # checked here: an entry that fails is a failed compile, not an error mid-run
            except (EntryRejected, CacheRefused) as e:
                self.status, self.why = "failed", str(e)
                return
            self.status = "ready"
            self.log.unlink(missing_ok=True)
        else:
            self.status = "failed"
            self.why = f"exit status {self.proc.returncode}: {last.strip() or 'no output'} (log: {self.log})"

    def describe(self) -> str:
        """How it went, for the line a run prints when it switches kernels."""
        took = f"{self.wall_s:.1f} s" if self.wall_s is not None else "?"
        if self.result.get("cached"):
            return f"found in the cache after {took} (another run compiled it)"
        cpu = self.result.get("cpu_s")
        return f"compiled in the background in {took}" + (f" ({cpu:.1f} s of CPU)" if cpu is not None else "")


_JOBS: dict[Path, BackgroundCompile] = {}  # one background compile per cache entry and process


def start(program: Program, entry: CacheEntry) -> tuple[BackgroundCompile, bool]:
    """The background compile of `entry` (from `program`): this process's running or finished one for the
    entry, else a new child process. Returns it and whether it is new."""
    job = _JOBS.get(entry.dir)
    if job is not None and job.poll() != "failed":
        return job, False
    entry.prepare()
    log = entry.dir / f"compile.{os.getpid()}.{time.monotonic_ns()}.log"
    with os.fdopen(create_new(log), "w") as out:
        # -P: not the current folder first on sys.path, where another checkout's tracelab/ would be found
        proc = subprocess.Popen([sys.executable, "-P", "-m", "tracelab.engine.compile_job", entry.key],
                                stdin=subprocess.PIPE, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
    assert proc.stdin is not None
    # written by a thread: a program bigger than the pipe's buffer would block this run until the child
    # has imported the engine and reads it
    threading.Thread(target=_hand_over, args=(proc.stdin, pickle.dumps(program)), daemon=True).start()
    job = _JOBS[entry.dir] = BackgroundCompile(entry, proc, log)
    return job, True


def _hand_over(pipe: IO[bytes], data: bytes) -> None:
    try:
        pipe.write(data)
        pipe.close()
    except OSError:  # the child died first: its exit status and log say why
        pass


def running() -> list[BackgroundCompile]:
    """The background compiles this process started that are still running."""
    return [job for job in _JOBS.values() if job.poll() == "running"]


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
