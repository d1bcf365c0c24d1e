"""Ctrl-C during a DuckDB query: stop the query at once, end the command with one line and status 130.

Python runs its SIGINT handler only between bytecodes of the main thread, and a DuckDB query holds the
main thread for as long as it runs (a long `tracelab sql` ignored Ctrl-C for 30 s and more). The C-level
handler does write the signal's number to a wakeup file descriptor at once; a thread waiting on it calls
the connection's interrupt(), so the query stops within DuckDB's next check (milliseconds)."""
from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable
from types import FrameType, TracebackType


class CtrlCStops:
    """`with CtrlCStops(interrupt):` Ctrl-C calls interrupt() from a watcher thread, and whatever the
    block then ends with (DuckDB's interrupt error, its own 'Query interrupted', or KeyboardInterrupt)
    becomes KeyboardInterrupt(what), which tracelab.cli.main prints as one line and exits 130. Off the
    main thread (where signals never arrive) the block runs as it is."""

    def __init__(self, interrupt: Callable[[], None], what: str = "the query was stopped") -> None:
        self.interrupt = interrupt
        self.what = what
        self.pressed = threading.Event()
        self.active = threading.current_thread() is threading.main_thread()

    def __enter__(self) -> CtrlCStops:
        if not self.active:
            return self
        self.finished = threading.Event()
        self.read_end, self.write_end = os.pipe()
        os.set_blocking(self.write_end, False)  # the C-level handler must never block on it
        self.previous_fd = signal.set_wakeup_fd(self.write_end, warn_on_full_buffer=False)
        self.previous_handler = signal.signal(signal.SIGINT, self._on_sigint)
        self.watcher = threading.Thread(target=self._watch, name="ctrl-c-watcher", daemon=True)
        self.watcher.start()
        return self

    def _watch(self) -> None:
        while not self.finished.is_set():
            if signal.SIGINT in os.read(self.read_end, 64) and not self.finished.is_set():
                self.pressed.set()
                self.interrupt()

    def _on_sigint(self, signum: int, frame: FrameType | None) -> None:
        # Python's own handler, run between bytecodes: DuckDB runs it too (it checks for signals at
        # times) and turns the KeyboardInterrupt into an error of its own, so note the press first
        self.pressed.set()
        raise KeyboardInterrupt(self.what)

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 tb: TracebackType | None) -> None:
        if not self.active:
            return
        signal.signal(signal.SIGINT, self.previous_handler)
        signal.set_wakeup_fd(self.previous_fd)
        self.finished.set()
        os.write(self.write_end, b"\0")  # wakes the watcher, which sees `finished`
        self.watcher.join()
        os.close(self.read_end)
        os.close(self.write_end)
        # a press the block swallowed (`runs` notes a run it could not read and goes on) still stops
        if self.pressed.is_set() or isinstance(error, KeyboardInterrupt):
            raise KeyboardInterrupt(self.what) from None


def ctrl_c_stops_queries(what: str = "the query was stopped") -> CtrlCStops:
    """`with ctrl_c_stops_queries():` around a reading command: Ctrl-C stops whatever query any of the
    store's connections is running (tracelab.store.sandbox.interrupt_queries), exit 130, one line."""
    from tracelab.store.sandbox import interrupt_queries  # DuckDB: imported only by the command that runs
    return CtrlCStops(interrupt_queries, what)


class CtrlCBetweenSteps:
    """`with CtrlCBetweenSteps() as ctrl_c:` around a loop that calls ctrl_c.check() between its steps:
    the first Ctrl-C only asks, and check() raises KeyboardInterrupt at the next step's end. A
    KeyboardInterrupt raised wherever Python's handler happens to run could land inside the trace
    writer's locked hand-over to its flusher thread or inside a compiled call (which numba turns into
    SystemError), and `play` then hung or printed a traceback; between steps nothing is half-done. A
    second Ctrl-C raises at once (for a step that never ends)."""

    def __init__(self, note: str = "stopping after this step (Ctrl-C again to stop at once)") -> None:
        self.note = note  # said on the first Ctrl-C: a compile that is running ends first
        self.requested = False
        self.active = threading.current_thread() is threading.main_thread()

    def __enter__(self) -> CtrlCBetweenSteps:
        if self.active:
            self.previous_handler = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def _on_sigint(self, signum: int, frame: FrameType | None) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print(f"\n{self.note}", file=sys.stderr)

    def check(self) -> None:
        if self.requested:
            raise KeyboardInterrupt

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self.active:
            signal.signal(signal.SIGINT, self.previous_handler)
