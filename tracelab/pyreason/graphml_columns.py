"""PyReason's GraphML mapping with array operations, for the common graph whose every value is a number or
a boolean in [0,1] (each is then `key` with [v,1]): sorting and np.unique instead of a Python dict per
node and edge, so that a big graph reads in about the time the engine's own mapping takes. The value-by-
value reading in graphml.py is the definition; tests/test_pyreason.py checks that both agree."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tracelab.engine.graphml_raw import RawGraph


@dataclass
class GraphFacts:
    """Graph facts with PyReason's labels (`Friends`, `color-red`), in PyReason's order: fact i sets
    labels[label[i]] on node args[i, 0] (and args[i, 1] for an edge, else -1) to bounds[i]."""
    labels: list[str] = field(default_factory=list)
    label: list[int] | np.ndarray = field(default_factory=list)
    args: list[tuple[int, int]] | np.ndarray = field(default_factory=list)
    bounds: list[tuple[float, float]] | np.ndarray = field(default_factory=list)
    _label_of: dict[str, int] = field(default_factory=dict)

    def add(self, label: str, lower: float, upper: float, a0: int, a1: int) -> None:
        lid = self._label_of.get(label)
        if lid is None:
            lid = self._label_of[label] = len(self.labels)
            self.labels.append(label)
        self.label.append(lid)
        self.args.append((a0, a1))
        self.bounds.append((lower, upper))

    def label_array(self) -> np.ndarray:
        return np.asarray(self.label, np.int32).reshape(-1)

    def args_array(self) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(self.args, np.int32).reshape(-1, 2))

    def bounds_array(self) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(self.bounds, np.float64).reshape(-1, 2))


def _first_last(group: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distinct values of `group` with the index of each one's first and of its last occurrence."""
    uniq, first = np.unique(group, return_index=True)
    _, last_rev = np.unique(group[::-1], return_index=True)
    return uniq, first, len(group) - 1 - last_rev


def numeric_facts(raw: RawGraph) -> GraphFacts | None:
    """The facts, or None when a value is not a number or boolean in [0,1], a key is a string key or
    missing, or directed and undirected edges mix (the value-by-value reading handles those)."""
    keys = [raw.keys.get(k) for k in raw.data_keys]
    if any(k is None or k.type == "string" for k in keys):
        return None
    d = raw.data
    kind, elem, kidx = d[:, 0], d[:, 1], d[:, 2]
    is_bool = np.array([k.type == "boolean" for k in keys], np.bool_)[kidx] if keys else np.zeros(0, np.bool_)
    booleans = np.where(raw.booleans < 0, np.nan, raw.booleans.astype(np.float64))
    values = np.where(is_bool, booleans, raw.numbers)
    if np.isnan(values).any() or (values < 0).any() or (values > 1).any():
        return None
    label_of = {name: i for i, name in enumerate(dict.fromkeys(k.name for k in keys))}  # (not list.index: K^2)
    labels, n_labels = list(label_of), max(len(label_of), 1)
    lab = np.array([label_of[k.name] for k in keys], np.int64)[kidx] if keys else np.zeros(0, np.int64)

    # nodes: a node's attributes in order of first appearance, each with its last value
    rows = np.flatnonzero(kind == 0)
    uniq, first, last = _first_last(elem[rows] * n_labels + lab[rows])
    order = np.lexsort((first, uniq // n_labels))
    node_args = np.column_stack([uniq // n_labels, np.full(len(uniq), -1)])[order]
    node_lab, node_val = (uniq % n_labels)[order], values[rows][last][order]

    # edges: networkx's DiGraph adjacency: per source node, targets in order of their first edge; an
    # undirected pair shares its attributes between both directions; parallel edges merge, later wins
    src, dst = raw.edges[:, 0].astype(np.int64), raw.edges[:, 1].astype(np.int64)
    undirected = np.where(raw.edges[:, 2] < 0, raw.graph_undirected, raw.edges[:, 2] == 0)
    if len(undirected) and undirected.any() != undirected.all():
        return None
    both = bool(len(undirected) and undirected[0])
    n = max(len(raw.nodes), 1)
    pair = np.minimum(src, dst) * n + np.maximum(src, dst) if both else src * n + dst
    pairs, pair_first_edge = np.unique(pair, return_index=True)
    rows = np.flatnonzero(kind == 1)
    uniq, first, last = _first_last(pair[elem[rows]] * n_labels + lab[rows])
    g_pair, g_lab, g_val = uniq // n_labels, uniq % n_labels, values[rows][last]
    g_edge = pair_first_edge[np.searchsorted(pairs, g_pair)]
    a, b = g_pair // n, g_pair % n
    if both:
        back = a != b
        a, b = np.concatenate([a, b[back]]), np.concatenate([b, a[back]])
        g_lab, g_val = np.concatenate([g_lab, g_lab[back]]), np.concatenate([g_val, g_val[back]])
        g_edge, first = np.concatenate([g_edge, g_edge[back]]), np.concatenate([first, first[back]])
    order = np.lexsort((first, g_edge, a))
    edge_args = np.column_stack([a, b])[order]

    out = GraphFacts(labels=labels)
    out.label = np.concatenate([node_lab, g_lab[order]])
    out.args = np.concatenate([node_args, edge_args]).astype(np.int32)
    val = np.concatenate([node_val, g_val[order]])
    out.bounds = np.column_stack([val, np.ones(len(val))])
    return out
