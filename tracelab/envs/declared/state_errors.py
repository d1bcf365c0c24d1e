"""What a world says when its state cannot be read as its spec asks (found while stepping, not when the
spec is read: it depends on what the rules made true): one located line, `FILE:LINE: KEY: ...`, a
WorldStateError, instead of a traceback from deep in a step."""
from __future__ import annotations

from tracelab.envs.declared.spec import Draw, ObservationPart, WorldSpec
from tracelab.envs.declared.spec_file import WorldStateError


def _in_world(world: int | None) -> str:
    return "" if world is None else f" in world {world}"


def no_index(spec: WorldSpec, part: ObservationPart, world: int | None = None) -> WorldStateError:
    """An index part none of whose atoms is [1,1]."""
    key = ("observation", "parts", spec.parts.index(part))
    fix = " (give the part `missing = N`," if spec.space in ("Box", "Dict") else " (use a Box or Dict with `missing`,"
    return spec.source.error(key, f"no atom of {part.atoms[0].pred}(...) is true{_in_world(world)}, so the part "
                                  f"has no index{fix} or make the rules keep one true)", WorldStateError)


def no_weights_hold(spec: WorldSpec, draw: Draw, world: int | None = None) -> WorldStateError:
    """A draw whose weights hold for no value."""
    weights = ", ".join(map(str, draw.weights[0])) if draw.weights else ""
    return spec.source.error((*draw.key, "weights"), f"no value's weights ({weights}, ...) hold"
                                                     f"{_in_world(world)}: nothing to draw from", WorldStateError)
