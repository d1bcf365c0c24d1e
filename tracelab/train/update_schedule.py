"""When the learners update and copy their targets: `worlds * updates_per_step` updates per learner
after each pass of the loop, once warm-up is over and every buffer holds a minibatch (the fraction of
an update carried over as credit), and a target copy every `target_every` steps."""
from __future__ import annotations

from collections.abc import Collection
from typing import Any

import numpy as np

from tracelab.train.config import TrainConfig
from tracelab.train.learner_protocol import Learner


class UpdateSchedule:
    def __init__(self, cfg: TrainConfig, worlds: int) -> None:
        self.cfg, self.worlds = cfg, worlds
        self.credit = 0.0       # updates owed but not yet made (updates_per_step * worlds may be fractional)
        self.synced_block = 0   # the last target_every block whose target copy was made

    def run(self, step: int, learners: Collection[Learner], rng: np.random.Generator) -> None:
        """The updates and target copies due after the pass that ended at `step`."""
        cfg = self.cfg
        if step < cfg.warmup or any(lr.buffer.size < cfg.batch for lr in learners):
            return
        self.credit += self.worlds * cfg.updates_per_step
        k = int(self.credit)
        self.credit -= k
        for learner in learners:
            for _ in range(k):
                learner.update(rng)
        block = step // cfg.target_every
        if block > self.synced_block:
            for learner in learners:
                learner.sync_target()
            self.synced_block = block

    def state(self) -> dict[str, Any]:
        return {"update_credit": self.credit, "synced_block": self.synced_block}

    def load_state(self, st: dict[str, Any]) -> None:
        self.credit, self.synced_block = float(st["update_credit"]), int(st["synced_block"])
