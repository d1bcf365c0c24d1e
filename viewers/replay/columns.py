"""Columns built once for several entities and sent to each entity as its slice. An archetype's
`.columns()` and a `TimeColumn` cost ~0.3-1 ms of Python (conversion and validation of each component)
however few rows they get, and one game has ~25 entities; building the columns over all the entities'
rows at once, then sending each entity its slice of the Arrow arrays, logs the same rows for a fraction
of that."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pyarrow as pa
import rerun as rr


class _TimeSlice:
    """What `send_columns` asks of an index column: its timeline's name and its Arrow array."""

    def __init__(self, name: str, array: pa.Array) -> None:
        self._name, self._array = name, array

    def timeline_name(self) -> str:
        return self._name

    def as_arrow_array(self) -> pa.Array:
        return self._array


class _ComponentSlice:
    """What `send_columns` asks of a component column: its descriptor and its Arrow list array."""

    def __init__(self, descriptor: rr.ComponentDescriptor, array: pa.Array) -> None:
        self._descriptor, self._array = descriptor, array

    def component_descriptor(self) -> rr.ComponentDescriptor:
        return self._descriptor

    def as_arrow_array(self) -> pa.Array:
        return self._array


def send_per_entity(rec: rr.RecordingStream, paths: Sequence[str], rows: Sequence[int] | np.ndarray,
                    indexes: Sequence[rr.TimeColumn], columns: Sequence[rr.ComponentColumn]) -> None:
    """`indexes` and `columns` hold the rows of several entities one after the other, `rows[k]` rows
    for `paths[k]`: send each entity its rows (one `send_columns` each, as if built for it alone)."""
    times = [(t.timeline_name(), t.as_arrow_array()) for t in indexes]
    components = [(c.component_descriptor(), c.as_arrow_array()) for c in columns]
    bounds = np.concatenate([[0], np.cumsum(rows)]).astype(np.int64).tolist()
    for path, lo, hi in zip(paths, bounds[:-1], bounds[1:]):
        rec.send_columns(path, indexes=[_TimeSlice(name, a.slice(lo, hi - lo)) for name, a in times],
                         columns=[_ComponentSlice(d, a.slice(lo, hi - lo)) for d, a in components])
