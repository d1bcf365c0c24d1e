"""Ctrl-C or SIGTERM landing anywhere in the trace writer's hand-over to its flusher thread never leaves
close() waiting forever (tracelab/store/writer.py, the module's doc). Python runs a signal handler where its
eval loop checks for one: at a function's start and just after a call returns. A profile function that
raises at the n-th such event (call, return, c_return) in the writer's and threading's code lands a
KeyboardInterrupt at each of those points in turn, deterministically. Before, one landing inside
threading.Condition.__enter__ just after it took the lock left the lock held, and close() waited forever
for the flusher (a SIGINT to tests/tui_writer_proc.py, a SIGTERM to `experiment --jobs 2`'s workers)."""
from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

import pytest

import tracelab.store.writer as writer_module
from tracelab.store.meta import read_meta
from tracelab.store.writer import TraceWriter

# the code a hand-over runs in the caller's thread (the rows are converted before it, by convert.py)
WATCHED = {os.path.abspath(writer_module.__file__), os.path.abspath(threading.__file__)}
CLOSE_WITHIN = 60  # seconds: a close that takes longer is the hang (it used to wait forever)
# where a handler can run: a Python function's start, and the return of a Python or C function (c_call
# comes before a call, where the eval loop runs no handler)
HANDLER_POINTS = {"call", "return", "c_return"}


def watched_events(frame: FrameType, event: str) -> bool:
    return event in HANDLER_POINTS and os.path.abspath(frame.f_code.co_filename) in WATCHED


def interrupt_at(n: int | None, seen: list[int]) -> Callable[[FrameType, str, Any], None]:
    """A profile function raising KeyboardInterrupt at the n-th watched event (None: only count them)."""
    def profile(frame: FrameType, event: str, arg: Any) -> None:  # noqa: ANN401
        if not watched_events(frame, event):
            return
        seen[0] += 1
        if seen[0] == n:
            sys.setprofile(None)
            raise KeyboardInterrupt
    return profile


def hand_over(w: TraceWriter) -> None:
    w.write_metrics(2, {"loss": 0.5})
    w.flush()


def interrupted_then_closed(run: Path, n: int | None, options: dict[str, int],
                            opened: list[TraceWriter]) -> tuple[int, str]:
    """Write, with a KeyboardInterrupt at the n-th watched event of one hand-over, then close() as
    TraceWriter's `with` does, all in one thread; returns how many events the hand-over had, and the status
    close() recorded."""
    w = TraceWriter(run, {"command": "test"}, flush_interval=0.05, **options)
    opened.append(w)
    w.write_metrics(1, {"loss": 1.0})
    seen = [0]
    sys.setprofile(interrupt_at(n, seen))
    try:
        hand_over(w)
    except KeyboardInterrupt:
        pass
    finally:
        sys.setprofile(None)
    w.close(status="interrupted")
    return seen[0], read_meta(run)["status"]


def closes(run: Path, n: int | None, options: dict[str, int]) -> tuple[int, str]:
    """interrupted_then_closed in a thread of its own (the profile and the locks are that thread's), failing
    the test if close() has not returned within CLOSE_WITHIN seconds instead of hanging it."""
    out: list[Any] = []
    opened: list[TraceWriter] = []
    t = threading.Thread(target=lambda: out.append(interrupted_then_closed(run, n, options, opened)),
                         daemon=True)
    t.start()
    t.join(CLOSE_WITHIN)
    if t.is_alive():
        writer_module._OPEN_WRITERS.discard(opened[0])  # or closing it at exit would hang pytest too
        pytest.fail(f"close() still waiting {CLOSE_WITHIN} s after an interrupt at watched event {n}")
    assert out, f"the writer failed after an interrupt at watched event {n}"
    return out[0]


# max_pending_rows=1: every write waits for the flusher (the back-pressure path)
@pytest.mark.parametrize("options", [{}, {"max_pending_rows": 1}], ids=["flush", "back-pressure"])
def test_an_interrupt_anywhere_in_the_hand_over_never_hangs_close(tmp_path: Path,
                                                                 options: dict[str, int]) -> None:
    events, status = closes(tmp_path / "count", None, options)
    assert events > 10 and status == "interrupted"
    for n in range(1, events + 1):
        assert closes(tmp_path / f"at-{n}", n, options)[1] == "interrupted", n
