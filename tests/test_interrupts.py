"""Ctrl-C that lands inside a compiled call: numba's dispatcher hands it back as SystemError("... returned a
result with an exception set") caused by the KeyboardInterrupt. `tracelab play` printed that traceback and
exited 1 in 1 of 8 Ctrl-C's (a repro that sends SIGINT once games are being played); it must count as an
interruption everywhere a run records how it ended."""
from __future__ import annotations

import json
from pathlib import Path

from tracelab.engine.errors import is_interrupt
from tracelab.store import TraceWriter


def _wrapped_ctrl_c() -> SystemError:
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as ctrl_c:
            raise SystemError("CPUDispatcher(<function f>) returned a result with an exception set") from ctrl_c
    except SystemError as e:
        return e


def test_a_ctrl_c_wrapped_by_the_dispatcher_is_an_interrupt() -> None:
    assert is_interrupt(KeyboardInterrupt()) and is_interrupt(SystemExit(143))
    assert is_interrupt(_wrapped_ctrl_c())
    assert not is_interrupt(SystemError("a real bug")) and not is_interrupt(ValueError("x"))
    looped = ValueError("a cycle of causes")
    looped.__context__ = RuntimeError("b")
    looped.__context__.__context__ = looped
    assert not is_interrupt(looped)  # ends, and says no


def test_a_run_stopped_by_a_wrapped_ctrl_c_is_closed_as_interrupted(tmp_path: Path) -> None:
    run = tmp_path / "run"
    try:
        with TraceWriter.open(run, {"command": "test"}):
            raise _wrapped_ctrl_c()
    except SystemError:
        pass
    assert json.loads((run / "meta.json").read_text())["status"] == "interrupted"
