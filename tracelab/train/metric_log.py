"""A training's metric rows: into its run and into every other sink (TensorBoard, a sweep's reporter),
what every log adds to the learner's figures (the mean training return since the last log, env
steps and updates per second), and what every evaluation adds to its own: its wall time, split into its
traced and untraced games, and the evaluations' share of the training's wall time so far.

The wall-clock figures differ between any two runs of the same seed (WALL_CLOCK_METRICS), and are not
in a checkpoint: the share is that of this process's training (since its start or resume)."""
from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tracelab.store.writer import TraceWriter
from tracelab.train.tensorboard import MetricSink

EVAL_SECONDS = "eval/seconds"                # one evaluation's wall time, its metrics and best policy included
EVAL_WALL_SHARE = "eval/wall_time_share"     # the evaluations' wall time over the training's, so far
EVAL_PART_SECONDS = {"traced": "eval/traced_seconds", "untraced": "eval/untraced_seconds"}
WALL_CLOCK_METRICS = ("env_steps_per_s", "updates_per_s", EVAL_SECONDS, EVAL_WALL_SHARE, *EVAL_PART_SECONDS.values())


class MetricLog:
    def __init__(self, writer: TraceWriter | None, sinks: Sequence[MetricSink] = ()) -> None:
        self.writer, self.sinks = writer, list(sinks)
        self.logged_step = -1             # the step of the last log
        self.last_loss: float | None = None
        self._rate_mark = (time.perf_counter(), 0, 0)  # (time, step, updates) of the last log
        self.eval_count = 0                 # evaluations timed in this process
        self.eval_seconds = 0.0             # their wall time
        self.eval_part_seconds = dict.fromkeys(EVAL_PART_SECONDS, 0.0)
        self._loop_seconds = 0.0            # wall time inside the training loop, before its last start
        self._loop_start: float | None = None

    def write(self, step: int, values: dict[str, float]) -> None:
        """Metric rows at `step`: into the run, and into every other sink."""
        if self.writer is not None:
            self.writer.write_metrics(step, values)
        for sink in self.sinks:
            sink.write(step, values)
            sink.flush()

    def complete(self, m: dict[str, float], step: int, updates: int, returns: list[float]) -> dict[str, float]:
        """`m` with what every log adds: the mean of the training `returns` ended since the last log, and
        the rates since then; remembers this log's loss and step."""
        now = time.perf_counter()
        t0, step0, upd0 = self._rate_mark
        if "loss" in m:
            self.last_loss = m["loss"]
        if returns:
            m["train_return"] = float(np.mean(returns))
        dt = max(now - t0, 1e-9)
        m["env_steps_per_s"] = (step - step0) / dt
        m["updates_per_s"] = (updates - upd0) / dt
        self._rate_mark = (now, step, updates)
        self.logged_step = step
        return m

    # ---- the evaluations' wall time ----
    def loop_started(self) -> None:
        self._loop_start = time.perf_counter()

    def loop_stopped(self) -> None:
        if self._loop_start is not None:
            self._loop_seconds += time.perf_counter() - self._loop_start
            self._loop_start = None

    def loop_seconds(self) -> float:
        """Wall time spent in the training loop by this process (the loop's current pass included)."""
        running = 0.0 if self._loop_start is None else time.perf_counter() - self._loop_start
        return self._loop_seconds + running

    def eval_share(self) -> float | None:
        """The evaluations' share of the training loop's wall time (None before the loop ran)."""
        total = self.loop_seconds()
        return min(1.0, self.eval_seconds / total) if total > 0 else None

    def evaluation_timed(self, seconds: float, parts: Mapping[str, float]) -> dict[str, float]:
        """Count an evaluation that took `seconds` of wall time (`parts`: of which its traced and untraced
        games, where the evaluation measured them); returns its wall-clock metrics."""
        self.eval_count += 1
        self.eval_seconds += seconds
        m = {EVAL_SECONDS: seconds}
        for part, name in EVAL_PART_SECONDS.items():
            if part in parts:
                self.eval_part_seconds[part] += parts[part]
                m[name] = float(parts[part])
        share = self.eval_share()
        if share is not None:
            m[EVAL_WALL_SHARE] = share
        return m

    # ---- checkpoints ----
    def state(self) -> dict[str, Any]:
        return {"last_loss": self.last_loss, "logged_step": self.logged_step}

    def load_state(self, st: dict[str, Any]) -> None:
        self.last_loss, self.logged_step = st["last_loss"], int(st["logged_step"])
