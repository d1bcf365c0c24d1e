"""Facts the env computes for each step (docs/worlds.md, `[[clock]]` and `[[nearest]]`): a clock's facts on
the episode's steps it names, and for each `who` of a `[[nearest]]` the fact of its nearest thing, from
the state the step starts from. Each is a group of the step's facts with one value picked (or none), as a
random draw is, so the one-world and the vector env set them through the same fused tables."""
from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
from numba import njit

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
    lines = np.array(n.lines if n.lines is not None else [], np.int64).reshape(-1, 2)
    out = np.empty((truth.shape[0], n.n_who), np.int64)
    _nearest_kernel(np.ascontiguousarray(truth), n.n_who, n.n_things, n.board_width, lines, n.lines is not None, out)
    return out


@njit(cache=True)
def _nearest_kernel(truth, n_who, n_things, width, lines, in_line, out):
    """nearest_things' loops, compiled (numpy's ~20 small operations cost ~150 µs a step)."""
    n_cells = truth.shape[1] // (n_who + n_things)
    cell = np.empty(n_who + n_things, np.int64)
    for w in range(truth.shape[0]):
        for k in range(n_who + n_things):
            cell[k] = -1
            for c in range(n_cells):
                if truth[w, k * n_cells + c]:
                    cell[k] = c
                    break
        for j in range(n_who):
            out[w, j] = -1
            if cell[j] < 0:
                continue
            best = FAR
            for t in range(n_things):
                c = cell[n_who + t]
                if c < 0:
                    continue
                dr = c // width - cell[j] // width
                dc = c % width - cell[j] % width
                key = abs(dr) + abs(dc)
                if in_line:
                    rank = 0 if dr == 0 and dc == 0 else -1
                    i = 0
                    while rank < 0 and i < lines.shape[0]:
                        a = lines[i, 0]
                        b = lines[i, 1]
                        if dr * b == dc * a and dr * a + dc * b > 0 and (a == 0 or dr % a == 0) \
                                and (b == 0 or dc % b == 0):
                            rank = i
                        i += 1
                    if rank < 0:
                        continue
                    key = key * lines.shape[0] + rank
                if key < best:
                    best = key
                    out[w, j] = t
