"""When a recorder that streams an env's games (envs/declared/recording.py) hands what it kept to the trace
writer: a write is a table per kind of row in the caller and a publication of every table in the writer's
thread (a Parquet part each, and a manifest; ended episodes ask for one at once), a cost that hardly
depends on its size. Written on a fixed clock, a recorder slowed by the machine's load or by heavier rows
(decisions and reward terms) published more often for the same games, and the writer's thread took about
40% of the stepping thread's CPU in `tracelab bench eval` at load 8 (docs/benchmarks.md, "`bench eval`").

The rule (WritePacing): a write is due
- when WRITE_ROWS step rows wait (the writer's buffers stay bounded), or
- when WRITE_INTERVAL_S of wall time have passed since the last write, and the stepping thread has spent
  at least WRITE_COST_FACTOR times the last write's cost (its CPU in the caller and the writer's CPU for its
  publication) of CPU since; so the writes cost the stepping thread's work at most 1 / WRITE_COST_FACTOR,
  and a quiet machine (a publication of a few ms) keeps the WRITE_INTERVAL_S latency; or
- WRITE_MAX_INTERVAL_S after the last write, whatever the CPU (a thread that waits between steps).
A live reader sees an ended episode that late at most, plus the writer's own delay."""
from __future__ import annotations

import time
from collections.abc import Callable

WRITE_ROWS = 4096
WRITE_INTERVAL_S = 0.25
WRITE_COST_FACTOR = 10.0
WRITE_MAX_INTERVAL_S = 2.0


class WritePacing:
    """Whether a write is due (the module's rule), asked after every step: `due()` reads the wall clock
    only, until the wall interval has passed; then the thread's CPU clock, and it tells when to look again.
    `wall` and `cpu` are the clocks (seconds: time.monotonic, time.thread_time of the stepping thread);
    `publish_cost` the writer's CPU seconds for its last publication (TraceWriter.last_publish_cpu_s)."""

    def __init__(self, publish_cost: Callable[[], float] = lambda: 0.0, *,
                 wall: Callable[[], float] = time.monotonic, cpu: Callable[[], float] = time.thread_time,
                 interval_s: float | None = None, cost_factor: float | None = None,
                 max_interval_s: float | None = None) -> None:
        """The module's constants unless given, read now (a program may set them before making its env)."""
        self.publish_cost, self.wall, self.cpu = publish_cost, wall, cpu
        self.interval_s = WRITE_INTERVAL_S if interval_s is None else interval_s
        self.cost_factor = WRITE_COST_FACTOR if cost_factor is None else cost_factor
        self.max_interval_s = WRITE_MAX_INTERVAL_S if max_interval_s is None else max_interval_s
        self.write_cost_s = 0.0  # the last write's CPU in the caller
        self._written_at = wall()
        self._cpu_at = cpu()
        self._look_at = self._written_at + self.interval_s  # no clock but the wall's before this

    def due(self) -> bool:
        now = self.wall()
        if now < self._look_at:
            return False
        if now >= self._written_at + self.max_interval_s:
            return True
        owed = self.cost_factor * (self.write_cost_s + self.publish_cost()) - (self.cpu() - self._cpu_at)
        if owed <= 0:
            return True
        # the thread's CPU runs no faster than the wall clock: nothing can be due before `owed` seconds
        self._look_at = min(now + owed, self._written_at + self.max_interval_s)
        return False

    def write(self, write: Callable[[], None]) -> None:
        """Do `write` (the recorder's) and count its CPU as this write's cost in the caller."""
        cpu0 = self.cpu()
        write()
        self._cpu_at = self.cpu()
        self.write_cost_s = self._cpu_at - cpu0
        self._written_at = self.wall()
        self._look_at = self._written_at + self.interval_s
