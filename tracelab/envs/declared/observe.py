"""A Box or Dict observation's numbers, read from the engine for a batch of worlds: what the one-world env
(world.py) and the vector env (vector_world.py) both report."""
from __future__ import annotations

import numpy as np

from tracelab.engine import Engine

from tracelab.envs.declared.spec import ObservationPart


def missing_index(part: ObservationPart, index: np.ndarray) -> bool:
    """True when an index part has no true atom in some world (index -1) and declares no `missing`."""
    return part.missing is None and bool((index < 0).any())


def part_numbers(part: ObservationPart, index: np.ndarray, engine: Engine, ids: np.ndarray) -> np.ndarray:
    """float32 [worlds, part.width]: `index` [worlds] is the part's index (-1: no atom true) for an
    index part; ids the part's atoms, read from `engine` (its truth for onehot and count: the lanes
    kernel reads a few atoms off its planes, where its bounds are a copy of every atom)."""
    if part.read == "nearest":
        index = nearest_cell(part, engine.is_true(ids))
    if part.read in ("index", "nearest"):
        numbers = index.astype(np.float32) if part.value_array is None else part.value_array[np.maximum(index, 0)]
        if part.missing is not None:
            numbers = np.where(index < 0, np.float32(part.missing), numbers)
        return numbers[:, None]
    if part.read == "count":
        return engine.is_true(ids).sum(axis=1, dtype=np.int64).astype(np.float32)[:, None]
    if part.read == "onehot":
        return engine.is_true(ids).astype(np.float32)
    lower = engine.lower[:, ids]
    if part.read == "lower":
        return lower.astype(np.float32)
    return np.stack([lower, engine.upper[:, ids]], axis=2).reshape(len(lower), -1).astype(np.float32)


def nearest_cell(part: ObservationPart, truth: np.ndarray) -> np.ndarray:
    """Per world, the board cell (index, -1: none) of the part's nearest thing: truth [worlds, (1 + things)
    * cells] of the `from` atoms, then each thing's. Distance: rows plus columns; a tie goes to the
    thing listed first; a thing on no cell, or no `from` cell, takes no part."""
    n_worlds = truth.shape[0]
    grid = truth.reshape(n_worlds, 1 + part.n_things, -1)
    where = np.where(grid.any(axis=2), grid.argmax(axis=2), -1)  # [worlds, 1 + things]: the first true cell
    rows, cols = np.divmod(where, part.board_width)
    dist = np.abs(rows[:, 1:] - rows[:, :1]) + np.abs(cols[:, 1:] - cols[:, :1])
    dist = np.where((where[:, 1:] >= 0) & (where[:, :1] >= 0), dist, np.iinfo(np.int64).max)
    best = dist.argmin(axis=1)  # the first of equal distances
    found = dist[np.arange(n_worlds), best] != np.iinfo(np.int64).max
    return np.where(found, where[np.arange(n_worlds), 1 + best], -1)
