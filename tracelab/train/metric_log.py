"""A training's metric rows: into its run and into every other sink (TensorBoard, a sweep's reporter),
and what every log adds to the learner's figures (the mean training return since the last log, env
steps and updates per second)."""
from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from tracelab.store.writer import TraceWriter
from tracelab.train.tensorboard import MetricSink


class MetricLog:
    def __init__(self, writer: TraceWriter | None, sinks: Sequence[MetricSink] = ()) -> None:
        self.writer, self.sinks = writer, list(sinks)
        self.logged_step = -1             # the step of the last log
        self.last_loss: float | None = None
        self._rate_mark = (time.perf_counter(), 0, 0)  # (time, step, updates) of the last log

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

    # ---- checkpoints ----
    def state(self) -> dict[str, Any]:
        return {"last_loss": self.last_loss, "logged_step": self.logged_step}

    def load_state(self, st: dict[str, Any]) -> None:
        self.last_loss, self.logged_step = st["last_loss"], int(st["logged_step"])
