"""PyReason's TemporalLogicIntegratedClassifier: the LogicIntegratedClassifier (classifier.py) that also
polls its model in the background and reasons on: every `poll_interval` (a `timedelta` of clock time, or
an int of the program's timesteps), if `poll_condition(identifier)` holds in the last interpretation (or
no condition is given), it classifies `input_fn()`, adds the facts (at the next timestep for a timedelta,
at the current one for an int, as PyReason's) and calls `reason(again=True, restart=False)`.

As in PyReason a daemon thread polls, started by the constructor. Its waits are on a clock object
(`clock=`, tracelab's): `WallClock` by default, or a `ManualClock` that a test advances, so no test waits
on wall-clock time; the int interval waits on the program's time (api.wait_for_time, woken by each
reason()). A poll holds the API's lock (api.LOCK) from the condition's query to the end of its reasoning,
so it never interleaves with the script's own calls; which of the two reasons first is the scheduler's,
as in PyReason. `stop()` ends the thread (PyReason has none: its thread lives until the process exits)."""
from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from datetime import timedelta
from typing import Any

import torch

from . import api
from .classifier import LogicIntegratedClassifier, ModelInterfaceOptions
from .objects import Fact, Query


class WallClock:
    """Seconds of time.monotonic(); waiting is Event.wait (ended early by the stop event)."""

    def now(self) -> float:
        return time.monotonic()

    def wait_until(self, deadline: float, stop: threading.Event) -> bool:
        """Wait until now() >= deadline; False when `stop` was set first."""
        while not stop.is_set():
            left = deadline - self.now()
            if left <= 0:
                return True
            stop.wait(left)
        return False


class ManualClock:
    """A clock that moves only when advance() is called (tests drive the polls with it)."""

    def __init__(self, start: float = 0.0) -> None:
        self._now = start
        self._moved = threading.Condition()

    def now(self) -> float:
        with self._moved:
            return self._now

    def advance(self, seconds: float) -> None:
        with self._moved:
            self._now += seconds
            self._moved.notify_all()

    def wake(self) -> None:
        """Wake the waiters (to see a stop event)."""
        with self._moved:
            self._moved.notify_all()

    def wait_until(self, deadline: float, stop: threading.Event) -> bool:
        with self._moved:
            self._moved.wait_for(lambda: stop.is_set() or self._now >= deadline)
            return not stop.is_set()


class TemporalLogicIntegratedClassifier(LogicIntegratedClassifier):
    """PyReason's constructor (model, class_names, identifier, interface_options, logic_program,
    poll_interval, poll_condition, input_fn) plus `clock` (tracelab's). `checks` counts the polls due so
    far, `polls` those that reasoned; wait_for_checks(n) waits for the poller to reach n."""

    def __init__(self, model: torch.nn.Module, class_names: Sequence[str], identifier: str = "classifier",
                 interface_options: ModelInterfaceOptions | None = None, logic_program: Any = None,
                 poll_interval: int | timedelta | None = None, poll_condition: str | None = None,
                 input_fn: Callable[[], Any] | None = None, *, clock: WallClock | ManualClock | None = None) -> None:
        super().__init__(model, class_names, identifier, interface_options)
        if poll_interval is not None and not isinstance(poll_interval, (int, timedelta)) \
                or isinstance(poll_interval, bool):
            raise TypeError(f"TemporalLogicIntegratedClassifier: poll_interval must be an int (timesteps), a "
                            f"datetime.timedelta or None, got {poll_interval!r}")
        self.logic_program = logic_program  # PyReason's; unused: there is one program (api.py's)
        self.poll_interval = poll_interval
        self.poll_condition = poll_condition
        self.input_fn = input_fn
        self.clock = clock or WallClock()
        self.checks = self.polls = 0
        self._counted = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if poll_interval is not None and input_fn is not None:
            # where the polls start is fixed here, not in the thread, so that nothing the script does
            # right after the constructor returns (advancing a clock, reasoning) is missed
            if isinstance(poll_interval, timedelta):
                target, args = self._poll_by_clock, (self.clock.now() + poll_interval.total_seconds(),)
            else:  # from the current time, or the end of the next reason()
                now = api.current_time()
                target, args = self._poll_by_steps, ((now, None) if now >= 0 else (None, len(api.REASONED_TO)))
            self._thread = threading.Thread(target=target, args=args, daemon=True, name=f"pyreason-poll-{identifier}")
            self._thread.start()

    def get_class_facts(self, t1: int, t2: int) -> list[Fact]:
        """A fact `class(identifier)` ([1,1]) per class, at t1..t2 (PyReason's)."""
        return [Fact(f"{c}({self.identifier})", name=f"{self.identifier}-{c}-fact", start_time=t1, end_time=t2)
                for c in self.class_names]

    def poll(self, t: int) -> bool:
        """One poll (what the thread does when one is due): if the condition holds, classify input_fn()
        into facts at t, add them and reason on. Whether it reasoned."""
        assert self.input_fn is not None
        with api.LOCK:
            if api.current_time() < 0:  # nothing reasoned yet: PyReason's poller waits for a program
                return False
            if self.poll_condition and not api.get_interpretation().query(
                    Query(f"{self.poll_condition}({self.identifier})")):
                return False
            _, _, facts = self(self.input_fn(), t, t)
            for f in facts:
                api.add_fact(f)
            api.reason(again=True, restart=False)
            return True

    def stop(self) -> None:
        """End the polling thread (and wait for it)."""
        self._stop.set()
        if isinstance(self.clock, ManualClock):
            self.clock.wake()
        api.wake_time_waiters()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()

    def wait_for_checks(self, n: int, timeout: float = 300.0) -> bool:
        """Wait until the poller has handled n due polls (a ceiling of `timeout` s, never the result)."""
        with self._counted:
            return self._counted.wait_for(lambda: self.checks >= n, timeout)

    def _count(self, reasoned: bool) -> None:
        with self._counted:
            self.checks += 1
            self.polls += int(reasoned)
            self._counted.notify_all()

    def _poll_by_clock(self, deadline: float) -> None:
        assert isinstance(self.poll_interval, timedelta)
        seconds = self.poll_interval.total_seconds()
        while self.clock.wait_until(deadline, self._stop):
            self._count(self.poll(api.current_time() + 1))
            deadline = max(deadline + seconds, self.clock.now()) if seconds > 0 else self.clock.now()

    def _poll_by_steps(self, first_seen: int | None, reasoning_no: int | None) -> None:
        steps = max(int(self.poll_interval or 0), 1)  # 0 would poll without end on a false condition
        if first_seen is None:  # the first time seen: the end of reason() number reasoning_no
            assert reasoning_no is not None
            if api.wait_for_time(lambda now: True, self._stop, reasoning_no + 1) is None:
                return
            first_seen = api.REASONED_TO[reasoning_no]
        due = first_seen + 1 + steps  # PyReason's: `steps` past the step after the first one seen
        while (now := api.wait_for_time(lambda now, due=due: now >= due, self._stop)) is not None:
            self._count(self.poll(now))
            due = now + steps
