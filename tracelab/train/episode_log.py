"""The training episodes of a run's worlds: their ids, lengths, returns and first steps, the returns
since the last metrics log, and the episode rows handed to the run's writer (begun and ended in batches,
one table per flush: a call per episode costs more than a pass of the loop)."""
from __future__ import annotations

from typing import Any

import numpy as np

from tracelab.store.writer import TraceWriter


class EpisodeLog:
    def __init__(self, worlds: int, writer: TraceWriter | None, *, logging: bool = True) -> None:
        """`logging` False: episode begins are written from `start_logging()` on (EnvTrainer
        starts logging in train(), after a checkpoint may have renumbered the games)."""
        self.worlds, self.writer, self.logging = worlds, writer, logging
        self.ids = np.zeros(worlds, np.int64)
        self.lengths = np.zeros(worlds, np.int64)
        self.returns = np.zeros(worlds)
        self.starts = np.zeros(worlds, np.int64)  # training step at which each world's episode began
        self.next_episode = 0
        self.returns_since_log: list[float] = []
        self._begun: list[dict[str, Any]] = []  # episode rows not yet handed to the writer
        self._ended: list[dict[str, Any]] = []
        self._continues: dict[int, int] = {}    # a game's new episode id -> the one it had (same-run resume)

    def new_id(self) -> int:
        ep = self.next_episode
        self.next_episode += 1
        return ep

    def begin(self, worlds: np.ndarray, step: int) -> None:
        for w in worlds.tolist():
            self.ids[w] = self.new_id()
        self.starts[worlds] = step
        self.lengths[worlds] = 0
        self.returns[worlds] = 0.0
        if self.logging:
            self._write_begins(worlds, step)

    def start_logging(self, step: int) -> None:
        """Write the begins of the games in progress, and every begin from now on."""
        if not self.logging:
            self.logging = True
            self._write_begins(np.arange(self.worlds), step)

    def _write_begins(self, worlds: np.ndarray, step: int) -> None:
        if self.writer is None:
            return
        for w in worlds.tolist():
            info = {"kind": "train", "train_step": int(self.starts[w])}
            if self.lengths[w]:
                info["resumed_at"] = step  # begun in the run this one resumes
                if int(self.ids[w]) in self._continues:
                    info["continues"] = self._continues[int(self.ids[w])]
            self._begun.append({"episode": int(self.ids[w]), "world": w, "t_start": 0, "info": info})

    def add_step(self, reward: np.ndarray) -> None:
        """Every world made a step that earned `reward` [W]."""
        self.lengths += 1
        self.returns += reward

    def end(self, worlds: np.ndarray, outcomes: list[str]) -> None:
        for w, outcome in zip(worlds.tolist(), outcomes):
            self.returns_since_log.append(float(self.returns[w]))
            if self.writer is not None:
                self._ended.append({"episode": int(self.ids[w]), "steps": int(self.lengths[w]),
                                    "outcome": outcome, "reward": float(self.returns[w])})

    def take_returns(self) -> list[float]:
        """The returns of the episodes ended since the last call."""
        out, self.returns_since_log = self.returns_since_log, []
        return out

    def flush(self) -> None:
        """Hand the rows gathered since the last flush to the writer."""
        if self.writer is not None and (self._begun or self._ended):
            self.writer.begin_episodes(self._begun)
            self.writer.end_episodes(self._ended)
        self._begun, self._ended = [], []

    def abort_open(self) -> None:
        """The games still running when training stops end as 'aborted' (a resumed run begins them again)."""
        if self.writer is None or not self.logging:
            return
        self._ended += [{"episode": int(self.ids[w]), "steps": int(self.lengths[w]), "outcome": "aborted",
                         "reward": float(self.returns[w])} for w in range(self.worlds)]
        self.flush()
        self.logging = False

    def renumber(self, first_free: int) -> None:
        """After a restore into the run the checkpoint came from: that run already holds the games in
        progress (ended 'aborted' at the stop) and, after a crash, episodes begun past the checkpoint. The
        games go on under new ids from `first_free` on; the begin info of one already under way names the
        id it continues."""
        self.next_episode = max(self.next_episode, first_free)
        for w in range(self.worlds):
            old = int(self.ids[w])
            self.ids[w] = self.new_id()
            self._continues[int(self.ids[w])] = old

    # ---- checkpoints (the keys checkpoints have always had: games.ep_* beside the trainer's games) ----
    def state(self) -> dict[str, Any]:
        return {"next_episode": self.next_episode, "returns_since_log": list(self.returns_since_log),
                "games": {"ep_len": self.lengths, "ep_return": self.returns, "ep_id": self.ids,
                          "ep_start": self.starts}}

    def load_state(self, st: dict[str, Any]) -> None:
        self.next_episode = int(st["next_episode"])
        self.returns_since_log = list(st["returns_since_log"])
        g = st["games"]
        self.lengths[...], self.returns[...] = g["ep_len"], g["ep_return"]
        self.ids[...], self.starts[...] = g["ep_id"], g["ep_start"]
