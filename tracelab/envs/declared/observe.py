"""A Box or Dict observation's numbers, read from the engine's bounds for a batch of worlds: what the
one-world env (world.py) and the vector env (vector_world.py) both report."""
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
    if part.read == "index":
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
