"""The actions both teams played in each GridWar world since its episode began.

The simulators' worlds are not pickled into a checkpoint (a rule engine's state is not meant to move
between processes): the checkpoint keeps these actions instead, and a restore replays them into a fresh
env. The game is deterministic given the actions, so the worlds come back exactly (the trainer checks
the observation they end in against the saved one)."""
from __future__ import annotations

from typing import Any

import numpy as np

from tracelab.game.scenario import NOTHING


class GameRecord:
    def __init__(self, worlds: int, max_steps: int, agents: int) -> None:
        self.history = np.zeros((worlds, max_steps, 2, agents), np.int16)  # spec action ids: red, blue per step

    def record(self, lengths: np.ndarray, red: np.ndarray, blue: np.ndarray) -> None:
        """Every world's step number `lengths` [W] of its episode: red's and blue's action ids [W, N]
        (-1 in worlds that ended: their record is dropped with the episode anyway)."""
        rows = np.arange(len(lengths))
        self.history[rows, lengths, 0] = red
        self.history[rows, lengths, 1] = blue

    def replay_into(self, sim: Any, lengths: np.ndarray) -> None:
        """Bring every world of `sim` to the state after its episode's first lengths[w] steps. Worlds start
        their replay so that all end together; before that they idle (both teams do nothing), then are
        reset."""
        history = self.history
        worlds, n = history.shape[0], history.shape[3]
        longest = int(lengths.max()) if worlds else 0
        start = longest - lengths
        sim.reset(worlds=np.ones(worlds, bool))
        idle = np.full((worlds, n), NOTHING, np.int64)
        for k in range(longest):
            begin = start == k
            if begin.any():
                sim.reset(worlds=begin)
            k_w = k - start
            playing = k_w >= 0
            red, blue = idle.copy(), idle.copy()
            idx = np.flatnonzero(playing)
            red[idx] = history[idx, k_w[idx], 0]
            blue[idx] = history[idx, k_w[idx], 1]
            sim.step(red, blue)
        if (lengths == 0).any():
            sim.reset(worlds=lengths == 0)

    # ---- checkpoints: games.history ----
    def state(self) -> dict[str, Any]:
        return {"history": self.history}

    def load_state(self, st: dict[str, Any]) -> None:
        self.history[...] = st["history"]
