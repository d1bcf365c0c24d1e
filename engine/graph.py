"""GraphML input, the way PyReason users bring graphs: every node attribute becomes a static unary fact on
the node, every edge attribute a static binary fact on the edge (both directions when undirected)."""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from typing import Any

from .errors import ProgramCheckError
from .parser import PREDICATE_RE
from .program import Fact, Literal, SourceLoc, Term

__all__ = ["Graph", "load_graphml"]

_NUM = r"([0-9]+(?:\.[0-9]+)?|\.[0-9]+)"
_BOUND_RE = re.compile(rf"\s*(?:\[\s*{_NUM}\s*,\s*{_NUM}\s*\]|{_NUM}\s*,\s*{_NUM})\s*")


@dataclass
class Graph:
    nodes: list[str] = field(default_factory=list)
    facts: list[Fact] = field(default_factory=list)  # static, at t = 0

    def predicates(self) -> dict[str, int]:
        """Predicate -> arity of every attribute: `known_predicates` for check_program."""
        return {f.literal.pred: len(f.literal.args) for f in self.facts}


def load_graphml(path: str | os.PathLike[str]) -> Graph:
    """Read a GraphML file. Attribute values: a number v in [0,1] is [v,v]; a boolean is [1,1] / [0,0];
    a string "l,u" or "[l,u]" is [l,u]. Anything else raises ProgramCheckError naming the file, the node
    or edge and the attribute. GraphML key defaults apply to elements that lack the attribute."""
    from xml.etree.ElementTree import ParseError

    import networkx as nx  # imported here: keeps `import tracelab.engine` fast for programs without graphs

    file = os.fspath(path)
    try:
        g = nx.read_graphml(file)
    except (ParseError, nx.NetworkXError) as e:
        raise ProgramCheckError(f"not a readable GraphML file: {e}", file) from e
    conv = _Converter(file)
    node_default = g.graph.get("node_default", {})
    edge_default = g.graph.get("edge_default", {})
    for n, attrs in g.nodes(data=True):
        for key, value in {**node_default, **attrs}.items():
            conv.fact(f"node '{n}'", key, value, (n,))
    for u, v, attrs in g.edges(data=True):
        # networkx copies the GraphML edge identifier into the edge data as "id": it is not a label
        items = {k: x for k, x in {**edge_default, **attrs}.items() if k != "id"}
        for key, value in items.items():
            conv.fact(f"edge ('{u}', '{v}')", key, value, (u, v))
            if not g.is_directed() and u != v:
                conv.fact(f"edge ('{u}', '{v}')", key, value, (v, u))
    return Graph(nodes=[str(n) for n in g.nodes], facts=conv.facts)


class _Converter:
    def __init__(self, file: str) -> None:
        self.file = file
        self.facts: list[Fact] = []
        self.arity: dict[str, int] = {}

    def fail(self, msg: str) -> ProgramCheckError:
        return ProgramCheckError(msg, self.file)

    def fact(self, where: str, key: str, value: Any, args: tuple[str, ...]) -> None:
        if not PREDICATE_RE.fullmatch(str(key)):
            raise self.fail(f"{where}, attribute '{key}': not a predicate name (a lower-case letter, then "
                            "letters, digits and '_'), so no rule could use it")
        if self.arity.setdefault(key, len(args)) != len(args):
            raise self.fail(f"{where}, attribute '{key}': set on nodes and on edges, but a predicate has "
                            "one arity")
        bound = _bound(value)
        if bound is None:
            raise self.fail(f"{where}, attribute '{key}': value {value!r} is not a bound (expected a number "
                            "in [0,1], a boolean, or a string 'l,u' or '[l,u]' with 0 <= l <= u <= 1)")
        lit = Literal(key, tuple(Term(str(a), is_var=False) for a in args), *bound)
        text = f"{key}({','.join(str(a) for a in args)})"
        self.facts.append(Fact(text, lit, static=True, loc=SourceLoc(self.file, 0, 0), text=text))


def _bound(value: Any) -> tuple[float, float] | None:
    if isinstance(value, bool):  # before numbers: bool is an int
        return (1.0, 1.0) if value else (0.0, 0.0)
    if isinstance(value, (int, float)):
        v = float(value)
        return (v, v) if 0.0 <= v <= 1.0 else None  # NaN fails the comparison too
    if isinstance(value, str):
        m = _BOUND_RE.fullmatch(value)
        if m is None:
            return None
        lo, hi = (float(x) for x in m.groups() if x is not None)
        return (lo, hi) if 0.0 <= lo <= hi <= 1.0 else None
    return None
