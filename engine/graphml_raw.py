"""What a GraphML reader hands over: nodes, edges and <data> values as arrays, before any value is
turned into a bound (graph.py does that). Both readers (the compiled scanner and expat) produce it."""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from .errors import ProgramCheckError

KEY_TYPES = ("boolean", "int", "long", "float", "double", "string")


@dataclass
class GraphKey:
    id: str
    name: str  # attr.name: the predicate
    domain: str  # for=: node | edge | all | graph ...
    type: str  # attr.type
    default: str | None = None

    @classmethod
    def of(cls, kid: str, attrs: Mapping[str, str], fail: Callable[[str], ProgramCheckError]) -> GraphKey:
        ktype = attrs.get("attr.type", "string")
        if ktype not in KEY_TYPES:
            raise fail(f"key '{kid}': unknown attr.type '{ktype}' (expected {', '.join(KEY_TYPES)})")
        return cls(kid, attrs.get("attr.name", kid), attrs.get("for", "all"), ktype)


@dataclass
class RawGraph:
    file: str
    nodes: list[str]  # in order of first appearance (a <node>, or an edge end)
    edges: np.ndarray  # int64 [E, 3]: source, target, directed (1 / 0, or -1: the graph's edgedefault)
    graph_undirected: bool
    keys: dict[str, GraphKey]  # by id, in document order
    data: np.ndarray  # int64 [D, 3]: element kind (0 node / 1 edge), element index, index into data_keys
    data_keys: list[str]  # key ids named by <data key=...>
    text: Callable[[int], str]  # data value i as text
    place: Callable[[int], tuple[int, int]]  # (line, column) of data value i
    numbers: np.ndarray  # float64 [D]: each value as a number, NaN if it is not one
    booleans: np.ndarray  # int8 [D]: 1 true / 0 false (also "1" / "0"), -1 neither


def boolean_of_text(text: str) -> int:
    """A <data> value as a boolean: 1 true / 0 false (case-insensitive, "1" / "0" too, spaces around), -1
    neither. Both readers read booleans this way (the compiled scanner for ASCII values, in bulk)."""
    t = text.strip().lower()
    return 1 if t in ("true", "1") else 0 if t in ("false", "0") else -1
