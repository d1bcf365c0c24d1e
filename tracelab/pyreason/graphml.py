"""A GraphML file read the way PyReason reads it (networkx's read_graphml, made a DiGraph, then
PyReason's GraphmlParser.parse_graph_attributes), as static facts at t = 0:
- a value that is a number in [0,1] (an int, long, float or double, a boolean (true is 1, false is 0), or
  a string of digits and dots) gives the attribute `key` the bound [v,1];
- a string "l,u" of two integers in {0,1} gives `key` the bound [l,u];
- any other value v gives the predicate `key-v` the bound [1,1] (`color="red"` is `color-red`);
- an undirected edge sets both directions; parallel edges merge their attributes, later ones winning;
- a key's <default> is not applied (networkx keeps it aside).
Hostile XML is refused by the engine's readers (engine/graph.py). Names become tracelab names (names.py)."""
from __future__ import annotations

import os
from typing import Any

import numpy as np

from tracelab.engine.errors import ProgramCheckError
from tracelab.engine.graph import Graph, check_names, edge_pairs, read_raw_graphml
from tracelab.engine.graphml_raw import RawGraph

from .graphml_columns import GraphFacts, numeric_facts
from .names import NameMap

_BOOL = {"true": True, "false": False, "1": True, "0": False}


def _value(text: str, ktype: str) -> object:
    """The Python value networkx gives a <data> text of this attr.type (ValueError if it cannot)."""
    if ktype == "boolean":
        return _BOOL[text.strip().lower()]
    if ktype in ("int", "long"):
        return int(text)
    if ktype in ("float", "double"):
        return float(text)
    return text


def attribute_fact(key: str, value: object) -> tuple[str, float, float]:
    """PyReason's mapping of one attribute: (label, lower, upper)."""
    if isinstance(value, (int, float)) and 0 <= value <= 1:
        return key, float(value), 1.0
    if isinstance(value, str) and value.replace(".", "").isdigit() and 0 <= float(value) <= 1:
        return key, float(value), 1.0
    if isinstance(value, str):
        parts = value.split(",")
        if len(parts) == 2:
            try:
                lo, up = int(parts[0]), int(parts[1])
            except ValueError:
                pass
            else:
                if 0 <= lo <= 1 and 0 <= up <= 1:
                    return key, float(lo), float(up)
    return f"{key}-{value}", 1.0, 1.0


def load_pyreason_graphml(path: str | os.PathLike[str], names: NameMap) -> Graph:
    """The graph's facts (static, at t = 0) with PyReason's mapping, predicates named through `names`.
    A graph whose values are all numbers or booleans in [0,1] is mapped with array operations
    (graphml_columns.py); any other goes through networkx's reading value by value (the definition)."""
    raw = read_raw_graphml(path)
    check_names(raw)
    facts = numeric_facts(raw)
    if facts is None:
        facts = _python_facts(raw)
    return _graph(list(raw.nodes), edge_pairs(raw), raw.file, facts, names)


def load_pyreason_networkx(graph: Any, names: NameMap) -> Graph:
    """A networkx graph (PyReason's `load_graph`) with the same mapping: networkx's DiGraph() of it (an
    undirected edge both ways), each attribute through `attribute_fact`. Node ids are their str()."""
    nodes = [str(n) for n in graph.nodes]
    index = {n: i for i, n in enumerate(graph.nodes)}
    facts = GraphFacts()
    for n, attrs in graph.nodes(data=True):
        for k, v in attrs.items():
            facts.add(*attribute_fact(str(k), v), index[n], -1)
    pairs: list[tuple[int, int]] = []
    directed = graph.is_directed()
    for src, dst, attrs in graph.edges(data=True):
        ends = [(index[src], index[dst])] + ([(index[dst], index[src])] if not directed and src != dst else [])
        for a, b in ends:
            pairs.append((a, b))
            for k, v in attrs.items():
                facts.add(*attribute_fact(str(k), v), a, b)
    edges = np.asarray(pairs, np.int32).reshape(-1, 2)
    return _graph(nodes, edges, "<networkx graph>", facts, names)


def _python_facts(raw: RawGraph) -> GraphFacts:
    """networkx's read_graphml and DiGraph(), then PyReason's mapping, one value at a time."""
    file = raw.file
    node_attrs: list[dict[str, object]] = [{} for _ in raw.nodes]
    adj: list[dict[int, dict[str, object]]] = [{} for _ in raw.nodes]  # DiGraph adjacency, insertion order
    edge_data: list[list[tuple[str, object]]] = [[] for _ in range(len(raw.edges))]
    for i, (kind, elem, kidx) in enumerate(raw.data.tolist()):
        key = raw.keys[raw.data_keys[kidx]]  # every key is declared (check_names)
        text = raw.text(i)
        try:
            value = _value(text, key.type)
        except (KeyError, ValueError):
            line, col = raw.place(i)
            raise ProgramCheckError(f"attribute '{key.name}': '{text}' is not a {key.type}", file, line, col) from None
        if kind == 0:
            node_attrs[elem][key.name] = value
        else:
            edge_data[elem].append((key.name, value))
    for e, (src, dst, directed) in enumerate(raw.edges.tolist()):
        undirected = raw.graph_undirected if directed < 0 else directed == 0
        attrs = adj[src].setdefault(dst, {})
        attrs.update(edge_data[e])
        if undirected and src != dst:
            adj[dst][src] = attrs  # networkx shares one dict between both directions
    out = GraphFacts()
    for n, attrs in enumerate(node_attrs):
        for k, v in attrs.items():
            out.add(*attribute_fact(k, v), n, -1)
    for src, targets in enumerate(adj):
        for dst, attrs in targets.items():
            for k, v in attrs.items():
                out.add(*attribute_fact(k, v), src, dst)
    return out


def _graph(nodes: list[str], edges: np.ndarray, file: str, facts: GraphFacts, names: NameMap) -> Graph:
    """The facts as the engine's Graph columns, PyReason labels named as tracelab predicates."""
    labels: list[str] = []
    arity: list[int] = []
    label_of: dict[str, int] = {}
    # per PyReason label, its tracelab label on nodes and on edges (PyReason keeps them apart: one
    # attribute on both is two predicates, NameMap.predicate)
    lab_map = np.zeros((len(facts.labels), 2), np.int32)
    fact_label, args = facts.label_array(), facts.args_array()
    on_edge = (args[:, 1] >= 0).astype(np.int64)
    used = np.zeros((len(facts.labels), 2), np.bool_)
    used[fact_label, on_edge] = True
    for j, label in enumerate(facts.labels):
        for ar in (1, 2):
            if not used[j, ar - 1]:
                continue
            name = names.predicate(label, ar)
            lid = label_of.get(name)
            if lid is None:
                lid = label_of[name] = len(labels)
                labels.append(name)
                arity.append(ar)
            lab_map[j, ar - 1] = lid
    fact_label = lab_map[fact_label, on_edge] if len(fact_label) else fact_label
    return Graph(nodes, labels, arity, fact_label, args, facts.bounds_array(), file, edges=edges)
