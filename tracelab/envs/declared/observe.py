"""What the one-world env (world.py) and the vector env (vector_world.py) both check and read of a Box or
Dict observation outside the compiled reader (observe_kernel.py): a missing index, and the `lower` and
`bounds` parts (numbers off the engine's bounds)."""
from __future__ import annotations

import numpy as np

from tracelab.engine import Engine

from tracelab.envs.declared.spec import ObservationPart


def missing_index(part: ObservationPart, index: np.ndarray) -> bool:
    """True when an index part has no true atom in some world (index -1) and declares no `missing`."""
    return part.missing is None and bool((index < 0).any())


def bound_numbers(part: ObservationPart, engine: Engine, ids: np.ndarray) -> np.ndarray:
    """float32 [worlds, part.width] of a `lower` part (each atom's lower bound) or a `bounds` part (each
    atom's lower then upper bound)."""
    lower = engine.lower[:, ids]
    if part.read == "lower":
        return lower.astype(np.float32)
    return np.stack([lower, engine.upper[:, ids]], axis=2).reshape(len(lower), -1).astype(np.float32)
