"""How long a test waits for a state before it gives up.

A ceiling, never an expectation: a test waits on a state or an event (a row visible, a process started, a
screen settled) and gives up only after PATIENCE seconds, so that a machine with both cores busy (the
suite under other work, CI beside a build) passes what a quiet one passes. How fast a thing happens is a
benchmark's question (`tracelab bench ...`), not a test's."""
from __future__ import annotations

import time
from collections.abc import Callable

PATIENCE = 600.0  # seconds


def wait_until(done: Callable[[], bool], what: str, poll: float = 0.05, patience: float = PATIENCE) -> None:
    """Poll `done` until it holds; fail naming `what` if it has not after `patience` seconds."""
    deadline = time.monotonic() + patience
    while not done():
        assert time.monotonic() < deadline, f"{what}: not after {patience:.0f} s"
        time.sleep(poll)
