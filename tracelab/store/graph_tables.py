"""A graph's facts and edges (tracelab.engine.Graph: GraphML and fact tables, as columns) as rows of the
store's `facts` and `edges` tables, built column by column: a million-edge graph is a few Arrow compute
calls, not a Python object per fact (Graph.fact(i) builds one; the rows here are the same)."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pyarrow as pa

from tracelab.engine.program import CONSTANT_RE, constant_text
from tracelab.store import arrow_build as ab
from tracelab.store.schema import SCHEMAS

# deferred: pyarrow.compute builds a wrapper per compute function (~7 MB resident), which a process that writes a
# game's run (a graph with no facts to compute on) never needs (docs/benchmarks/history.md, "Memory of long runs")


def _quoted_names(names: pa.Array) -> pa.Array | None:
    """Each node as the rule language writes it (engine.program.constant_text): bare when it can be,
    quoted otherwise; None when every node is bare. The regular expression runs in Arrow, only the nodes
    that need quotes in Python."""
    import pyarrow.compute as pc
    bare = pc.match_substring_regex(names, f"^(?:{CONSTANT_RE.pattern})$")
    if pc.all(bare).as_py() is not False:
        return None
    texts = names.to_pylist()
    for i in np.flatnonzero(~ab.bools_to_numpy(bare)).tolist():
        texts[i] = constant_text(texts[i])
    return ab.strings(texts)


def _atom_texts(labels: pa.Array, names: pa.Array, a0: np.ndarray, a1: np.ndarray) -> pa.Array:
    """label(a) or label(a,b) per row (a1 < 0: no second argument)."""
    import pyarrow.compute as pc
    opening, comma, closing, nothing = (ab.scalar(s) for s in ("(", ",", ")", ""))
    first = pc.take(names, ab.from_numpy(a0))
    binary = a1 >= 0
    if binary.all():
        return pc.binary_join_element_wise(labels, opening, first, comma, pc.take(names, ab.from_numpy(a1)),
                                           closing, nothing)
    if not binary.any():
        return pc.binary_join_element_wise(labels, opening, first, closing, nothing)
    flags = ab.from_numpy(binary)
    second = pc.if_else(flags, pc.take(names, ab.from_numpy(np.where(binary, a1, 0))), nothing)
    return pc.binary_join_element_wise(labels, opening, first, pc.if_else(flags, comma, nothing), second,
                                       closing, nothing)


def _bound_texts(bounds: np.ndarray) -> pa.Array:
    """`:[l,u]` per row, formatted as Literal.__str__ does ({:g}); each distinct bound formatted once (a
    bound as one complex number: a 1-D unique, several times faster than unique(axis=0))."""
    import pyarrow.compute as pc
    pairs = np.ascontiguousarray(bounds, np.float64).view(np.complex128).reshape(-1)
    if len(pairs) and (pairs == pairs[0]).all():  # the usual graph: every fact [1,1]
        lo, up = bounds[0]
        return pa.repeat(ab.scalar(f":[{lo:g},{up:g}]"), len(pairs))
    unique, inverse = np.unique(pairs, return_inverse=True)
    texts = ab.strings([f":[{b.real:g},{b.imag:g}]" for b in unique.tolist()])
    return pc.take(texts, ab.from_numpy(inverse.reshape(-1).astype(np.int32)))


def graph_fact_table(graph: Any, file_name: Callable[[str], str] | None = None, first_id: int = 0) -> pa.Table:
    """The graph's facts as `facts` rows numbered from `first_id`, in the graph's order (Engine.facts
    puts them first): name and text `label(a,b)` (constants quoted as in rules), literal
    `label(a,b):[l,u]`, the window and static flag, the graph's file (as `file_name` records it) and line 0,
    and the episode a fact table gave the fact (NULL: every episode)."""
    n = graph.n_facts
    if n == 0:  # a game's graph: its facts are the program's
        return ab.empty_table(SCHEMAS["facts"])
    import pyarrow.compute as pc
    a0, a1 = graph.fact_args[:, 0], graph.fact_args[:, 1]
    labels = pc.take(ab.strings(list(graph.labels)), ab.from_numpy(np.asarray(graph.fact_label)))
    plain = ab.strings(list(graph.nodes))
    quoted = _quoted_names(plain)
    atom = _atom_texts(labels, plain, a0, a1)  # the literal writes constants as they are
    name = atom if quoted is None else _atom_texts(labels, quoted, a0, a1)
    literal = pc.binary_join_element_wise(atom, _bound_texts(graph.fact_bounds), ab.scalar(""))
    windows = graph.windows
    episode = graph.episodes
    columns = {
        "fact": ab.from_numpy(np.arange(first_id, first_id + n, dtype=np.int32)),
        "name": name, "text": name, "literal": literal,
        "start": ab.from_numpy(windows[:, 0].astype(np.int32)), "end": ab.from_numpy(windows[:, 1].astype(np.int32)),
        "static": ab.from_numpy(np.asarray(graph.statics, dtype=np.bool_)),
        "file": pa.repeat(ab.column([file_name(graph.file) if file_name and graph.file else graph.file],
                                    pa.string())[0], n),
        "line": ab.from_numpy(np.zeros(n, np.int32)),
        "episode": ab.from_numpy(np.asarray(episode, dtype=np.int64), null=episode < 0),
    }
    return ab.table(columns, SCHEMAS["facts"])


def edges_table(edges: np.ndarray) -> pa.Table:
    """`edges` rows of a graph's (source, target) node-id pairs (Graph.edges)."""
    pairs = np.asarray(edges, np.int32).reshape(-1, 2)
    return ab.table({"source": ab.from_numpy(pairs[:, 0]), "target": ab.from_numpy(pairs[:, 1])}, SCHEMAS["edges"])
