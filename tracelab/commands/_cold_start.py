"""A first `tracelab play` on empty caches starts its games at once (issue 40).

Compiling the kernels a declared world steps on takes about a minute of CPU on one core (docs/benchmarks.md,
"Issue 40: the first play of a fresh install"). When they are not in numba's cache, play runs them as their
Python source instead (engine/numba_python.py: same code, same trace, slower per step) and starts a
background process, in its own session, that plays one episode of the same command on the compiled kernels
into a throwaway run: that fills the cache for the next runs. When it finishes while the games go on, play
switches to the compiled kernels between two episodes. TRACELAB_COLD_START=wait compiles first, as before
(the background process itself runs so). The background process writes its output to a log in tracelab's
cache folder (LOG_FOLDER), which it removes when it succeeds; a failure's last line names it.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import IO, Any

COLD_START = "TRACELAB_COLD_START"  # "background" (the default) or "wait"

LOG_FOLDER = "cold-start"  # under tracelab's cache folder (compile_cache.cache_root's parent)
# the child: the same play command on the compiled kernels, one episode, into a run it deletes; its log
# (argv[1], "-": none) is removed when it succeeds
_CHILD = ("import os, sys, tempfile\n"
          "from tracelab.cli import main\n"
          "with tempfile.TemporaryDirectory(prefix='tracelab-compile-') as tmp:\n"
          "    code = main([*sys.argv[2:], '--episodes', '1', '--run', os.path.join(tmp, 'run')])\n"
          "if code == 0 and sys.argv[1] != '-':\n"
          "    os.unlink(sys.argv[1])\n"
          "sys.exit(code)\n")


def _play_kernels(spec: Any) -> tuple[Any, ...]:
    """The kernels whose first compile a play of `spec` waits for (the smaller ones compile in seconds)."""
    from tracelab.engine import kernel
    from tracelab.envs.declared import fused, observe_kernel
    box = (observe_kernel.observe_lower,) if spec.space in ("Box", "Dict") else ()
    return (kernel.step_worlds, fused.fused_step, fused._make_buffers, *box)


class ColdStart:
    """The Python kernels of this play and the background compile that will replace them."""

    def __init__(self, kernels: Any, job: subprocess.Popen, watched: tuple[Any, ...], log: Path | None = None) -> None:
        self.kernels, self.job, self.watched, self.log = kernels, job, watched, log
        self.started = time.monotonic()
        self.switched_after: int | None = None  # the episodes played on the Python kernels, once switched

    def between_episodes(self, played: int) -> None:
        """After an episode: the compiled kernels from here on when the background compile has cached them."""
        from tracelab.engine.numba_cache import all_cached
        if self.switched_after is not None or self.job.poll() != 0:
            return
        self.kernels.restore()
        if all_cached(self.watched):
            self.switched_after = played
        else:  # it ended without caching them (another interpreter?): stay on Python, never compile here
            self.kernels.swap()

    def final_line(self) -> str:
        if self.switched_after is not None:
            return (f"tracelab: the kernels compiled in the background; episodes after the first "
                    f"{self.switched_after} ran on them")
        if self.job.poll() is None:
            return (f"tracelab: the kernels are still compiling in the background (pid {self.job.pid}); the next "
                    f"run loads them from the cache")
        if self.job.returncode == 0:
            return "tracelab: the kernels compiled in the background; the next run loads them from the cache"
        said = f"; its output: {self.log}" if self.log is not None else ""
        return (f"tracelab: the background compile of the kernels failed (exit status {self.job.returncode}"
                f"{said}); the next run tries again (or compile first: {COLD_START}=wait)")


def start_compile(argv: list[str]) -> tuple[subprocess.Popen, Path | None]:
    """The background process that compiles the kernels of the play command `argv` (one episode of it, on
    the compiled kernels), in its own session (a Ctrl-C of this run leaves it to finish), its output into a
    new log file (None when tracelab's cache folder cannot hold one: the output is then dropped)."""
    log, out = _new_log()
    try:
        job = subprocess.Popen([sys.executable, "-P", "-c", _CHILD, str(log or "-"), *argv],
                               env={**os.environ, COLD_START: "wait"}, stdin=subprocess.DEVNULL,
                               stdout=out if out is not None else subprocess.DEVNULL, stderr=subprocess.STDOUT,
                               start_new_session=True)
    finally:
        if out is not None:
            out.close()  # the child holds its own copy
    return job, log


def _new_log() -> tuple[Path | None, IO[str] | None]:
    """A new file in tracelab's cache folder, private to this user (created new, never through a link),
    open for writing; (None, None) when the folder cannot be used."""
    from tracelab.engine.compile_cache import CacheRefused, private_folder, cache_root
    from tracelab.engine.safe_files import create_new
    folder = cache_root().parent / LOG_FOLDER
    log = folder / f"compile.{os.getpid()}.{time.time_ns()}.log"
    try:
        private_folder(folder.parent, follow_symlinks=True)
        private_folder(folder, follow_symlinks=False)
        return log, os.fdopen(create_new(log), "w")
    except (CacheRefused, OSError):
        return None, None


def start_if_cold(spec: Any, kernel: str, argv: list[str]) -> ColdStart | None:
    """When the kernels a play of `spec` steps on are not in numba's cache (and the engine's counting
    kernel is the one asked for): their Python source from now on in this process, a background compile
    of them, and one line on stderr saying so. None when they are cached, or cannot be told."""
    if os.environ.get(COLD_START, "background") == "wait" or kernel not in ("auto", "counting"):
        return None
    # every module of a play's step is loaded before the swap: the swap replaces what is loaded
    import tracelab.envs.declared.gym_env  # noqa: F401
    import tracelab.envs.declared.recording  # noqa: F401
    import tracelab.envs.declared.world  # noqa: F401
    from tracelab.engine.numba_cache import all_cached
    from tracelab.engine.numba_python import PythonKernels
    from tracelab.first_run_figures import measured
    watched = _play_kernels(spec)
    if all_cached(watched) is not False:
        return None
    job, log = start_compile(argv)
    kernels = PythonKernels()
    kernels.swap()
    print(f"tracelab: first run: the engine's kernels are not compiled yet, so the games play on their Python "
          f"source (slower per step) while a background process (pid {job.pid}) compiles them for the next runs "
          f"({measured('play')})", file=sys.stderr, flush=True)
    return ColdStart(kernels, job, watched, log)
