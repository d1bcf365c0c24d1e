"""GraphML input, the way PyReason users bring graphs: every node attribute becomes a static unary fact on
the node, every edge attribute a static binary fact on the edge (both directions when undirected).

A graph is columns (node list, fact arrays), not a Python object per fact: a million-edge graph is a few
arrays. Files are read by a compiled scanner (graphml_scan.py) when they keep to the plain GraphML that
graph tools write, else by the complete expat reader (graphml_expat.py); both refuse hostile XML.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import numpy as np

from .errors import ProgramCheckError
from .grounding_limit import limit_in_force
from .graphml_expat import read_graphml_expat, read_key_element
from .graphml_raw import GraphKey, RawGraph, boolean_of_text
from .memory import release_freed_memory
from .program import PREDICATE_RE, Fact, Literal, SourceLoc, Term, constant_text, unwritable_constant
from .safe_files import read_bytes

__all__ = ["Graph", "load_graphml", "read_raw_graphml"]

_NUM = r"([0-9]+(?:\.[0-9]+)?|\.[0-9]+)"
_BOUND_RE = re.compile(rf"\s*(?:\[\s*{_NUM}\s*,\s*{_NUM}\s*\]|{_NUM}\s*,\s*{_NUM})\s*")
# a GraphML file is read whole into memory: refused past this (the million-edge graph of `tracelab bench
# engine` is ~75 MB), and never waited on (a FIFO is refused)
GRAPH_FILE_CAP = 4 << 30
# a smaller file is read by expat (~1 ms of CPU per 12 KB) rather than the compiled scanner, whose module
# and four cached kernels cost ~35 ms of CPU to load in a new process (docs/benchmarks/history.md, "PyReason's
# API"); the two read alike (tests/test_graphml_differential.py)
SCANNER_MIN_BYTES = 64 << 10
_UTF8_BOM = b"\xef\xbb\xbf"
_UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")
_S, _EQ = rb"[ \t\r\n]", rb"[ \t\r\n]*=[ \t\r\n]*"
# the XML declaration as XML 1.0 writes it (expat takes more, and decides on those files itself)
_XML_DECL_RE = re.compile(
    rb"<\?xml" + _S + rb"+version" + _EQ + rb"""(["'])1\.[0-9]+\1"""
    rb"(?:" + _S + rb"+encoding" + _EQ + rb"""(["'])([A-Za-z][A-Za-z0-9._-]*)\2)?"""
    rb"(?:" + _S + rb"+standalone" + _EQ + rb"""(["'])(?:yes|no)\4)?""" + _S + rb"*\?>")
# declared encodings in which expat reads ASCII bytes as ASCII (only "utf-8" reads UTF-8 as UTF-8)
_ASCII_ENCODINGS = frozenset((b"us-ascii", b"ascii", b"utf8", b"utf_8", b"iso-8859-1", b"latin-1", b"latin1"))


@dataclass
class Graph:
    """Nodes and static facts at t = 0, as columns. Fact i sets labels[fact_label[i]] on node fact_args[i, 0]
    (and fact_args[i, 1] for an edge label; -1 for a node label) to [fact_bounds[i, 0], fact_bounds[i, 1]].
    Node ids index `nodes`. Facts come in the graph's order (docs/language.md, "Graphs")."""
    nodes: list[str] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    label_arity: list[int] = field(default_factory=list)
    fact_label: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    fact_args: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int32))
    fact_bounds: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.float64))
    file: str = "<graph>"
    # fact tables (facttable.py) also give windows and static flags; a GraphML fact is static at t = 0
    fact_window: np.ndarray | None = None  # int64 [F, 2]: start, end
    fact_static: np.ndarray | None = None  # bool [F]
    # the graph's edges as node-id pairs (source, target), an undirected edge both ways: where the edge
    # heads of rules without {infer_edges} may land under `%edge_heads graph` (attributes or not)
    edges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int32))
    # a fact table's `episode` column: int64 [F], the one episode of a recorded reasoning a fact belongs to,
    # -1 for every episode (the engine runs every fact it is given: tracelab.reasoning picks them)
    fact_episode: np.ndarray | None = None

    # built on demand, not kept: a million GraphML facts would hold 17 MB of zeros and ones
    @property
    def windows(self) -> np.ndarray:
        return self.fact_window if self.fact_window is not None else np.zeros((self.n_facts, 2), np.int64)

    @property
    def statics(self) -> np.ndarray:
        return self.fact_static if self.fact_static is not None else np.ones(self.n_facts, np.bool_)

    @property
    def episodes(self) -> np.ndarray:
        return self.fact_episode if self.fact_episode is not None else np.full(self.n_facts, -1, np.int64)

    def concat(self, other: Graph) -> Graph:
        """This graph's facts, then other's (its nodes and labels mapped onto this graph's)."""
        node_ids = {n: i for i, n in enumerate(self.nodes)}
        nodes = list(self.nodes)
        for n in other.nodes:
            if n not in node_ids:
                node_ids[n] = len(nodes)
                nodes.append(n)
        node_map = np.array([node_ids[n] for n in other.nodes], np.int32)
        labels, arity = list(self.labels), list(self.label_arity)
        label_ids = {name: i for i, name in enumerate(labels)}
        label_map = np.zeros(len(other.labels), np.int32)
        for j, (name, ar) in enumerate(zip(other.labels, other.label_arity)):
            i = label_ids.get(name)
            if i is None:
                i = label_ids[name] = len(labels)
                labels.append(name)
                arity.append(ar)
            elif arity[i] != ar:
                raise ProgramCheckError(f"predicate '{name}' has {ar} argument(s) here but {arity[i]} in "
                                        f"{self.file}", other.file)
            label_map[j] = i
        args = other.fact_args.copy()
        args[:, 0] = node_map[args[:, 0]] if len(args) else args[:, 0]
        edge = args[:, 1] >= 0
        args[edge, 1] = node_map[other.fact_args[edge, 1]]
        edges = np.concatenate([self.edges, node_map[other.edges]]) if len(other.edges) else self.edges
        episodes = None if self.fact_episode is None and other.fact_episode is None else \
            np.concatenate([self.episodes, other.episodes])
        return Graph(nodes, labels, arity, np.concatenate([self.fact_label, label_map[other.fact_label]]),
                     np.concatenate([self.fact_args, args]), np.concatenate([self.fact_bounds, other.fact_bounds]),
                     self.file, np.concatenate([self.windows, other.windows]),
                     np.concatenate([self.statics, other.statics]), edges, episodes)

    @property
    def n_facts(self) -> int:
        return len(self.fact_label)

    def predicates(self) -> dict[str, int]:
        """Predicate -> arity of every attribute that sets a fact: `known_predicates` for check_program."""
        used = np.unique(self.fact_label)
        return {self.labels[i]: self.label_arity[i] for i in used.tolist()}

    def fact(self, i: int) -> Fact:
        """Fact i as a program fact (named by its text)."""
        a0, a1 = (int(x) for x in self.fact_args[i])
        args = (self.nodes[a0],) if a1 < 0 else (self.nodes[a0], self.nodes[a1])
        pred = self.labels[int(self.fact_label[i])]
        lo, up = (float(x) for x in self.fact_bounds[i])
        lit = Literal(pred, tuple(Term(a, is_var=False) for a in args), lo, up)
        text = f"{pred}({','.join(map(constant_text, args))})"
        start, end = (0, 0) if self.fact_window is None else (int(x) for x in self.fact_window[i])
        static = self.fact_static is None or bool(self.fact_static[i])
        return Fact(text, lit, start, end, static=static, loc=SourceLoc(self.file, 0, 0),
                    text=text)

    @property
    def facts(self) -> list[Fact]:
        """Every fact as a program fact (one object per fact: for small graphs and tests)."""
        return [self.fact(i) for i in range(self.n_facts)]


def load_graphml(path: str | os.PathLike[str]) -> Graph:
    """Read a GraphML file. Attribute values: a number v in [0,1] is [v,v]; a boolean is [1,1] / [0,0];
    a string "l,u" or "[l,u]" is [l,u]. Anything else raises ProgramCheckError naming the file, the line,
    the node or edge and the attribute. GraphML key defaults apply to elements that lack the attribute.
    (docs/language.md, "Graphs".)"""
    graph = _to_graph(read_raw_graphml(path))  # the file's bytes and the scanner's columns are freed here,
    release_freed_memory(graph.n_facts)         # and given back to the system if they were big
    return graph


def read_raw_graphml(path: str | os.PathLike[str]) -> RawGraph:
    """A GraphML file's nodes, edges and <data> values before any value becomes a bound (for readers with
    another attribute mapping, such as PyReason's: tracelab/pyreason/graphml.py)."""
    file = os.fspath(path)
    data = read_bytes(file, GRAPH_FILE_CAP, what="GraphML file")
    raw = _scan(file, data) if len(data) >= SCANNER_MIN_BYTES else None
    if raw is None:  # small, or outside the scanner's subset: the complete reader
        data = b""
        raw = read_graphml_expat(file)
    return raw


def _scan(file: str, data: bytes) -> RawGraph | None:
    """The compiled scanner's reading of `data`, or None when the file leaves its subset (graphml_scan.py)."""
    from . import graphml_scan as S  # numba kernels: loaded only for a file big enough to need them
    start = _scan_start(data)
    if start is None:
        return None
    if b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):
        return None  # a lone CR ends a line for expat: lines are counted one way, at LF
    b = np.frombuffer(data, np.uint8)
    status, scanned = S.scan_graphml(b, start)
    if status != S.SCAN_OK:
        return None
    keys: dict[str, GraphKey] = {}
    for s, e in scanned["key_elems"].tolist():  # few: each read by expat, as the whole file would be
        key = read_key_element(data[s:e], file)
        if key is None:
            return None
        keys[key.id] = key
    nodes = _node_ids(scanned["pool"], scanned["node_off"])
    data_keys = [data[s:e].decode("utf-8") for s, e in scanned["key_spans"].tolist()]
    s, e = scanned["graph_tag"][S.G_EDGEDEFAULT_S:].tolist()
    undirected = s >= 0 and data[s:e] == b"undirected"
    d = scanned["data"]

    def text(i: int) -> str:
        return data[int(d[i, S.D_START]):int(d[i, S.D_END])].decode("utf-8")

    def place(i: int) -> tuple[int, int]:  # as expat counts: lines at LF, columns in characters
        pos = int(d[i, S.D_POS])
        line_start = data.rfind(b"\n", 0, pos) + 1
        return data.count(b"\n", 0, pos) + 1, len(data[line_start:pos].decode("utf-8")) + 1

    booleans = scanned["booleans"]
    for i in np.flatnonzero(booleans == S.BOOLEAN_UNKNOWN).tolist():
        booleans[i] = boolean_of_text(text(i))
    return RawGraph(
        file=file, nodes=nodes, edges=scanned["edges"], graph_undirected=undirected, keys=keys,
        data=d[:, S.D_KIND:S.D_KEY + 1], data_keys=data_keys, text=text, place=place,
        numbers=scanned["numbers"], booleans=booleans)


def _scan_start(data: bytes) -> int | None:
    """Where the scanner starts: past a UTF-8 byte order mark and the XML declaration. None when the
    file is in an encoding the scanner does not read, or declares itself in a way it does not know."""
    if data[:2] in _UTF16_BOMS:
        return None
    start = len(_UTF8_BOM) if data.startswith(_UTF8_BOM) else 0
    if not data.startswith(b"<?xml", start) or data[start + 5:start + 6] not in (b" ", b"\t", b"\r", b"\n"):
        return start  # no declaration (a PI named xml... is left to expat by the scanner)
    m = _XML_DECL_RE.match(data, start)
    if m is None:
        return None
    encoding = (m.group(3) or b"utf-8").lower()
    if encoding != b"utf-8" and not (encoding in _ASCII_ENCODINGS and data.isascii()):
        return None
    return m.end()


def _node_ids(pool: np.ndarray, off: np.ndarray) -> list[str]:
    """Node id i is pool[off[i]:off[i+1]] (UTF-8): decoded at once, split at inserted line breaks (the
    scanner takes no attribute value holding one: XML makes a line break there a space)."""
    n = len(off) - 1
    if n <= 0:
        return []
    out = np.empty(len(pool) + n - 1, np.uint8)
    breaks = off[1:-1] + np.arange(n - 1)  # where the line breaks go, between ids
    keep = np.ones(len(out), np.bool_)
    keep[breaks] = False
    out[keep] = pool
    out[breaks] = 10
    return out.tobytes().decode("utf-8").split("\n")


def check_names(raw: RawGraph) -> None:
    """What every reading of a GraphML file refuses (ProgramCheckError): a node id that cannot be a
    constant of the rule language, and a <data key> that names no <key> (located at its first use)."""
    joined = "\0".join(raw.nodes)  # one scan for what unwritable_constant refuses, a loop only if found
    if "\n" in joined or "\r" in joined or ('"' in joined and "'" in joined) or not all(raw.nodes):
        for name in raw.nodes:
            why = unwritable_constant(name)
            if why is not None:
                raise ProgramCheckError(f"node id {name!r} cannot be a constant of the rule language: {why}",
                                        raw.file)
    del joined
    for k in raw.data_keys:
        if k not in raw.keys:
            i = int(np.argmax(raw.data[:, 2] == raw.data_keys.index(k)))
            raise _fail_at(raw, i, f"<data key=\"{k}\"> names no <key>")


def _to_graph(raw: RawGraph) -> Graph:
    """Columns of facts in the graph's order (docs/language.md, "Graphs")."""
    file = raw.file
    check_names(raw)
    labels: list[str] = []
    arity: list[int] = []
    label_of: dict[str, int] = {}
    parts: list[tuple[np.ndarray, ...]] = []  # (order key, label, a0, a1, lower, upper) per chunk
    n_nodes, n_edges = len(raw.nodes), len(raw.edges)
    src = raw.edges[:, 0].astype(np.int32)
    dst = raw.edges[:, 1].astype(np.int32)
    undirected = np.where(raw.edges[:, 2] < 0, raw.graph_undirected, raw.edges[:, 2] == 0)
    d_kind, d_elem = raw.data[:, 0], raw.data[:, 1]
    d_seq = np.arange(len(raw.data), dtype=np.int64)
    key_index = {k: i for i, k in enumerate(raw.data_keys)}
    check_fact_count(raw)
    # each key's data rows, in document order: one stable sort, not a pass over the data per key (which made
    # 25,000 keys take minutes)
    by_key = np.argsort(raw.data[:, 2], kind="stable")
    key_ends = np.searchsorted(raw.data[by_key, 2], np.arange(len(raw.data_keys) + 1))
    # facts in the graph's order: node facts (node order), then edge facts (edge order); an element's
    # attributes in document order, then key defaults it lacks in key order
    for kpos, (kid, key) in enumerate(raw.keys.items()):
        k = key_index.get(kid)
        sel = by_key[key_ends[k]:key_ends[k + 1]] if k is not None else np.zeros(0, np.int64)
        for kind, count in ((0, n_nodes), (1, n_edges)):
            rows = sel[d_kind[sel] == kind]
            if key.domain not in ("all", ("node", "edge")[kind]):
                if len(rows):
                    raise _fail_at(raw, int(rows[0]), f"key '{kid}' is declared for {key.domain}, but used on "
                                   f"{('nodes', 'edges')[kind]}")
                continue
            elem = d_elem[rows]
            order = (elem << 32) + d_seq[rows]
            lo, up = _bounds(raw, key, kind, rows, elem)
            if key.default is not None:
                lacking = np.ones(count, np.bool_)
                lacking[elem] = False
                extra = np.flatnonzero(lacking)
                if len(extra):
                    dl, du = _default_bound(raw, key, kind, int(extra[0]))
                    elem = np.concatenate([elem, extra])
                    order = np.concatenate([order, (extra << 32) + (1 << 31) + kpos])
                    lo = np.concatenate([lo, np.full(len(extra), dl)])
                    up = np.concatenate([up, np.full(len(extra), du)])
            if not len(elem):
                continue
            if not PREDICATE_RE.fullmatch(key.name):
                raise _fail_at(raw, int(rows[0]) if len(rows) else -1, f"{_where(raw, kind, int(elem[0]))}, "
                               f"attribute '{key.name}': not a predicate name (a lower-case letter, then letters, "
                               "digits and '_'), so no rule could use it")
            lid = label_of.get(key.name)
            if lid is None:
                lid = label_of[key.name] = len(labels)
                labels.append(key.name)
                arity.append(kind + 1)
            elif arity[lid] != kind + 1:
                raise _fail_at(raw, int(rows[0]) if len(rows) else -1, f"{_where(raw, kind, int(elem[0]))}, "
                               f"attribute '{key.name}': set on nodes and on edges, but a predicate has one arity")
            lab = np.full(len(elem), lid, np.int32)
            if kind == 0:
                parts.append((order, lab, elem.astype(np.int32), np.full(len(elem), -1, np.int32), lo, up))
                continue
            # an undirected edge also sets the reverse direction, right after (a self-loop once)
            parts.append(((1 << 62) + 2 * order, lab, src[elem], dst[elem], lo, up))
            back = undirected[elem] & (src[elem] != dst[elem])
            parts.append(((1 << 62) + 2 * order[back] + 1, lab[back], dst[elem[back]], src[elem[back]],
                          lo[back], up[back]))
    if parts:
        order, lab, a0, a1, lo, up = (np.concatenate(c) for c in zip(*parts))
        if len(order) < 2 or (order[1:] > order[:-1]).all():  # one attribute per element: in order already
            fact_label, fact_args, fact_bounds = lab, np.column_stack([a0, a1]), np.column_stack([lo, up])
        else:
            s = np.argsort(order, kind="stable")
            fact_label, fact_args = lab[s], np.column_stack([a0[s], a1[s]])
            fact_bounds = np.column_stack([lo[s], up[s]])
    else:
        fact_label = np.zeros(0, np.int32)
        fact_args, fact_bounds = np.zeros((0, 2), np.int32), np.zeros((0, 2), np.float64)
    return Graph(raw.nodes, labels, arity, fact_label, np.ascontiguousarray(fact_args, np.int32),
                 np.ascontiguousarray(fact_bounds, np.float64), file, edges=edge_pairs(raw))


def check_fact_count(raw: RawGraph) -> None:
    """Refuse a graph whose facts would pass the grounding limit (engine/grounding_limit.py, the CLI's
    --max-groundings), before they are built: a key's <default> gives a fact to every node (or edge)
    lacking the attribute, so a few KB of keys over many nodes could ask for billions."""
    n_nodes, n_edges = len(raw.nodes), len(raw.edges)
    facts = 2 * len(raw.data)  # an undirected edge's attribute sets both directions
    for key in raw.keys.values():
        if key.default is not None:
            facts += 2 * n_edges if key.domain == "edge" else n_nodes if key.domain == "node" else n_nodes + 2 * n_edges
    limit, source = limit_in_force()
    if facts > limit:
        raise ProgramCheckError(f"the graph could make {facts:,} facts (its attributes and its keys' defaults "
                                f"over {n_nodes:,} nodes and {n_edges:,} edges), more than the limit of {limit:,} "
                                f"({source}; --max-groundings raises it); refused before they are built", raw.file)


def edge_pairs(raw: RawGraph) -> np.ndarray:
    """The graph's edges as (source, target) node-id pairs, an undirected edge both ways (Graph.edges)."""
    src = raw.edges[:, 0].astype(np.int32)
    dst = raw.edges[:, 1].astype(np.int32)
    undirected = np.where(raw.edges[:, 2] < 0, raw.graph_undirected, raw.edges[:, 2] == 0)
    back = undirected & (src != dst)
    return np.concatenate([np.column_stack([src, dst]), np.column_stack([dst[back], src[back]])]).astype(np.int32)


def _where(raw: RawGraph, kind: int, elem: int) -> str:
    if kind == 0:
        return f"node {raw.nodes[elem]!r}"
    return f"edge ({raw.nodes[int(raw.edges[elem, 0])]!r}, {raw.nodes[int(raw.edges[elem, 1])]!r})"


def _fail_at(raw: RawGraph, row: int, msg: str) -> ProgramCheckError:
    if row < 0:  # a key's default value: no place in the document for that element
        return ProgramCheckError(msg, raw.file)
    line, col = raw.place(row)
    return ProgramCheckError(msg, raw.file, line, col)


_HINT = "(a bound is a number in [0,1], a boolean, or a string 'l,u' or '[l,u]' with 0 <= l <= u <= 1)"


def _bounds(raw: RawGraph, key: GraphKey, kind: int, rows: np.ndarray,
            elem: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per value, its bound (vectorised for numbers and booleans); a bad value raises naming it."""
    def bad(i: int, shown: str, what: str) -> ProgramCheckError:
        return _fail_at(raw, int(rows[i]), f"{_where(raw, kind, int(elem[i]))}, attribute '{key.name}': "
                        f"value {shown} is {what} {_HINT}")

    if key.type in ("float", "double", "int", "long"):
        v = raw.numbers[rows].copy()
        for i in np.flatnonzero(np.isnan(v)).tolist():  # what the scanner left: long or odd numbers
            try:
                v[i] = float(raw.text(int(rows[i])))
            except ValueError:
                raise bad(i, repr(raw.text(int(rows[i])).strip()), f"not of type {key.type}") from None
        if key.type in ("int", "long"):
            whole = np.isfinite(v) & (v == np.floor(v))
            if not whole.all():
                i = int(np.argmin(whole))
                raise bad(i, repr(raw.text(int(rows[i])).strip()), f"not of type {key.type}")
        ok = (v >= 0.0) & (v <= 1.0)
        if not ok.all():
            i = int(np.argmin(ok))
            shown = raw.text(int(rows[i])).strip() if key.type in ("int", "long") else repr(float(v[i]))
            raise bad(i, shown, "not a bound")
        return v, v.copy()
    if key.type == "boolean":
        t = raw.booleans[rows]
        if (t < 0).any():
            i = int(np.argmax(t < 0))
            raise bad(i, repr(raw.text(int(rows[i]))), "not a boolean")
        v = t.astype(np.float64)
        return v, v.copy()
    lo, up = np.empty(len(rows)), np.empty(len(rows))
    for i, r in enumerate(rows.tolist()):
        b = _string_bound(raw.text(r))
        if b is None:
            raise bad(i, repr(raw.text(r)), "not a bound")
        lo[i], up[i] = b
    return lo, up


def _default_bound(raw: RawGraph, key: GraphKey, kind: int, elem: int) -> tuple[float, float]:
    text = key.default or ""
    b: tuple[float, float] | None
    if key.type == "boolean":
        t = text.strip().lower()
        b = (1.0, 1.0) if t in ("true", "1") else (0.0, 0.0) if t in ("false", "0") else None
    elif key.type == "string":
        b = _string_bound(text)
    else:
        try:
            v = float(text)
        except ValueError:
            v = float("nan")
        b = (v, v) if 0.0 <= v <= 1.0 else None
    if b is None:
        raise ProgramCheckError(f"{_where(raw, kind, elem)}, attribute '{key.name}': the key's default value "
                                f"{text!r} is not a bound {_HINT}", raw.file)
    return b


def _string_bound(value: str) -> tuple[float, float] | None:
    m = _BOUND_RE.fullmatch(value)
    if m is None:
        return None
    lo, hi = (float(x) for x in m.groups() if x is not None)
    return (lo, hi) if 0.0 <= lo <= hi <= 1.0 else None
