"""Facts the env computes for each step (docs/worlds.md, `[[clock]]` and `[[nearest]]`): a clock's facts on
the episode's steps it names, and for each `who` of a `[[nearest]]` the fact of its nearest thing, from
the state the step starts from. Each is a group of the step's facts with one value picked (or none), as a
random draw is, so the one-world and the vector env set them through the same fused tables."""
from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from tracelab.engine import Engine
from tracelab.envs.declared.spec import Atom, NearestFacts, WorldSpec

FAR = np.iinfo(np.int64).max


class ComputedFacts:
    """The spec's clocks, then each `[[nearest]]`'s who in order: one group of values each."""

    def __init__(self, spec: WorldSpec, ids: Callable[[Iterable[Atom]], np.ndarray]) -> None:
        self.clocks = spec.clocks
        self.nearest = [(n, ids(n.where)) for n in spec.nearest_facts]
        self.value_ids = [[ids(c.atoms)] for c in spec.clocks] + \
            [[ids([a]) for a in per_who] for n in spec.nearest_facts for per_who in n.atoms]
        self.value_bounds = [[np.array([[a.lower, a.upper] for a in c.atoms], np.float64)] for c in spec.clocks] + \
            [[np.array([[a.lower, a.upper]], np.float64) for a in per_who]
             for n in spec.nearest_facts for per_who in n.atoms]

    def __len__(self) -> int:
        return len(self.value_ids)

    def picks(self, engine: Engine, steps: np.ndarray) -> np.ndarray:
        """int64 [worlds, groups]: each group's value for the next step (-1: none); `steps` [worlds] is
        the number of that step in its episode (0: the first after reset)."""
        out = np.full((len(steps), len(self)), -1, np.int64)
        for k, c in enumerate(self.clocks):
            out[:, k] = np.where(steps % c.every == c.at, 0, -1)
        col = len(self.clocks)
        for n, ids in self.nearest:
            out[:, col:col + n.n_who] = nearest_things(n, engine.is_true(ids))
            col += n.n_who
        return out


def nearest_things(n: NearestFacts, truth: np.ndarray) -> np.ndarray:
    """[worlds, who]: the index of each who's nearest thing (-1: none qualifies), from the truth of the
    `where` atoms [worlds, (who + things) * cells]: distance in rows plus columns, only things in `lines`
    when given (key distance * lines + the line's rank, the same cell ranking first), the first listed
    thing on a tie."""
    worlds = truth.shape[0]
    grid = truth.reshape(worlds, n.n_who + n.n_things, -1)
    cell = np.where(grid.any(axis=2), grid.argmax(axis=2), -1)
    row, col = np.divmod(cell, n.board_width)
    dr = row[:, None, n.n_who:] - row[:, :n.n_who, None]  # [worlds, who, things]
    dc = col[:, None, n.n_who:] - col[:, :n.n_who, None]
    key = np.abs(dr) + np.abs(dc)
    if n.lines is not None:
        rank = np.where((dr == 0) & (dc == 0), 0, -1)
        for i, (a, b) in reversed(list(enumerate(n.lines))):  # the first line listed wins
            along = (dr * b == dc * a) & (dr * a + dc * b > 0)
            if a:
                along &= dr % a == 0
            if b:
                along &= dc % b == 0
            rank = np.where(along & (rank != 0), i, rank)
        key = np.where(rank >= 0, key * len(n.lines) + rank, FAR)
    found = (cell[:, :n.n_who, None] >= 0) & (cell[:, None, n.n_who:] >= 0)
    key = np.where(found, key, FAR)
    best = key.argmin(axis=2)
    return np.where(np.take_along_axis(key, best[..., None], axis=2)[..., 0] != FAR, best, -1)
