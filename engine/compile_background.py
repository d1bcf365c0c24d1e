"""A compile of a program's kernel in a background process while a run goes on on the counting kernel
(Engine(kernel="compiled", background_compile=True)). The child is `python -m tracelab.engine.compile_job
KEY`, which compiles as `tracelab compile` does (compile_job.py, whose docstring says how); this side
starts it, hands it the program through a pipe and checks on it between steps, and the Engine takes the
kernel over once it is ready. It imports nothing of the Engine, so core.py can import it."""
from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO

from .compile_cache import CacheEntry, CacheRefused, EntryRejected
from .program import Program
from .safe_files import create_new


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
