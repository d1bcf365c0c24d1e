"""A graph's facts and edges (tracelab.engine.Graph: GraphML and fact tables, as columns) as rows of the
store's `facts` and `edges` tables, built column by column: a million-edge graph is a few Arrow compute
calls, not a Python object per fact (Graph.fact(i) builds one; the rows here are the same)."""
from __future__ import annotations

from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from tracelab.engine.program import CONSTANT_RE, constant_text
from tracelab.store.schema import SCHEMAS


def _quoted_names(names: pa.Array) -> pa.Array | None:
    """Each node as the rule language writes it (engine.program.constant_text): bare when it can be,
    quoted otherwise; None when every node is bare. The regular expression runs in Arrow, only the nodes
    that need quotes in Python."""
    bare = pc.match_substring_regex(names, f"^(?:{CONSTANT_RE.pattern})$")
    if pc.all(bare).as_py() is not False:
        return None
    texts = names.to_pylist()
    for i in np.flatnonzero(~bare.to_numpy(zero_copy_only=False)).tolist():
        texts[i] = constant_text(texts[i])
    return pa.array(texts, pa.string())


def _atom_texts(labels: pa.Array, names: pa.Array, a0: np.ndarray, a1: np.ndarray) -> pa.Array:
    """label(a) or label(a,b) per row (a1 < 0: no second argument)."""
    first = pc.take(names, pa.array(a0))
    binary = a1 >= 0
    if binary.all():
        return pc.binary_join_element_wise(labels, "(", first, ",", pc.take(names, pa.array(a1)), ")", "")
    if not binary.any():
        return pc.binary_join_element_wise(labels, "(", first, ")", "")
    flags = pa.array(binary)
    second = pc.if_else(flags, pc.take(names, pa.array(np.where(binary, a1, 0))), "")
    return pc.binary_join_element_wise(labels, "(", first, pc.if_else(flags, ",", ""), second, ")", "")


def _bound_texts(bounds: np.ndarray) -> pa.Array:
    """`:[l,u]` per row, formatted as Literal.__str__ does ({:g}); each distinct bound formatted once (a
    bound as one complex number: a 1-D unique, several times faster than unique(axis=0))."""
    pairs = np.ascontiguousarray(bounds, np.float64).view(np.complex128).reshape(-1)
    if len(pairs) and (pairs == pairs[0]).all():  # the usual graph: every fact [1,1]
        lo, up = bounds[0]
        return pa.repeat(pa.scalar(f":[{lo:g},{up:g}]", pa.string()), len(pairs))
    unique, inverse = np.unique(pairs, return_inverse=True)
    texts = pa.array([f":[{b.real:g},{b.imag:g}]" for b in unique.tolist()], pa.string())
    return pc.take(texts, pa.array(inverse.reshape(-1).astype(np.int32)))


def graph_fact_table(graph: Any, first_id: int = 0) -> pa.Table:
    """The graph's facts as `facts` rows numbered from `first_id`, in the graph's order (Engine.facts
    puts them first): name and text `label(a,b)` (constants quoted as in rules), literal
    `label(a,b):[l,u]`, the window and static flag, the graph's file and line 0, and the episode a
    fact table gave the fact (NULL: every episode)."""
    n = graph.n_facts
    a0, a1 = graph.fact_args[:, 0], graph.fact_args[:, 1]
    labels = pc.take(pa.array(graph.labels, pa.string()), pa.array(graph.fact_label))
    plain = pa.array(graph.nodes, pa.string())
    quoted = _quoted_names(plain)
    atom = _atom_texts(labels, plain, a0, a1)  # the literal writes constants as they are
    name = atom if quoted is None else _atom_texts(labels, quoted, a0, a1)
    literal = pc.binary_join_element_wise(atom, _bound_texts(graph.fact_bounds), "")
    windows = graph.windows
    episode = graph.episodes
    columns = {
        "fact": pa.array(np.arange(first_id, first_id + n, dtype=np.int32)),
        "name": name, "text": name, "literal": literal,
        "start": pa.array(windows[:, 0].astype(np.int32)), "end": pa.array(windows[:, 1].astype(np.int32)),
        "static": pa.array(graph.statics), "file": pa.repeat(pa.scalar(graph.file, pa.string()), n),
        "line": pa.array(np.zeros(n, np.int32)),
        "episode": pa.array(episode, pa.int64(), mask=episode < 0),
    }
    return pa.Table.from_arrays([columns[f.name] for f in SCHEMAS["facts"]], schema=SCHEMAS["facts"])


def edges_table(edges: np.ndarray) -> pa.Table:
    """`edges` rows of a graph's (source, target) node-id pairs (Graph.edges)."""
    pairs = np.asarray(edges, np.int32).reshape(-1, 2)
    return pa.Table.from_arrays([pa.array(np.ascontiguousarray(pairs[:, 0])),
                                 pa.array(np.ascontiguousarray(pairs[:, 1]))], schema=SCHEMAS["edges"])
