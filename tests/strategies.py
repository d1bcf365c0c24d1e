"""Hypothesis strategies: small random rule programs (as text, then parsed), small graphs and external facts.

Programs are emitted as TEXT so that every example also exercises the parser and its checks. Every rule is
safe by construction (each variable occurs in a binding clause, one whose bound does not contain [0,1]).
Bounds come from a quarter grid, so 1 - x and intersections are exact in binary and the reference and the
compiled engine can be compared with ==.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from hypothesis import strategies as st
from tracelab.engine import register_annotation
from tracelab.engine.graph import Graph
from tracelab.engine.parser import parse_program
from tracelab.engine.program import INCONSISTENCY_POLICIES, Literal, Program, clause_binds

GRID = (0.0, 0.25, 0.5, 0.75, 1.0)
VARIABLES = ("X", "Y", "Z")
FRESH_NODES = ("m0", "m1")  # constants no program mentions: external facts introduce them as new nodes
POLICIES = tuple(p for p in INCONSISTENCY_POLICIES if p != "abort")  # abort stops the run: tested apart

Bound = tuple[float, float]


@dataclass(frozen=True)
class ExtFact:
    pred: str
    args: tuple[str, ...]
    lower: float
    upper: float
    static: bool = False

    def __str__(self) -> str:
        static = " static" if self.static else ""
        return f"{self.pred}({','.join(self.args)}):[{self.lower:g},{self.upper:g}]{static}"


@dataclass
class Scenario:
    """A program with its graph and the external facts to add before each step."""
    text: str
    program: Program
    steps: int
    graph: Graph
    externals: list[list[ExtFact]]  # per step, the same in every world
    world_externals: list[list[list[ExtFact]]] = field(default_factory=list)  # [world][step]

    @property
    def graph_edges(self) -> list[tuple[str, str]]:
        """The graph's edges as node names (the reference evaluator's `graph_edges`)."""
        return [(self.graph.nodes[a], self.graph.nodes[b]) for a, b in self.graph.edges.tolist()]

    def __str__(self) -> str:  # what hypothesis prints for a falsifying example
        lines = [self.text.rstrip(), f"# graph nodes {self.graph.nodes}",
                 *(f"# graph fact {f.literal} @{f.start}" for f in self.graph.facts),
                 *(f"# graph edge {a} -> {b}" for a, b in self.graph_edges),
                 *(f"# before step {t}: {', '.join(map(str, fs))}" for t, fs in enumerate(self.externals) if fs)]
        for w, per_step in enumerate(self.world_externals):
            lines += [f"# world {w} before step {t}: {', '.join(map(str, fs))}"
                      for t, fs in enumerate(per_step) if fs]
        return "\n".join(lines)

    __repr__ = __str__

    def _repr_pretty_(self, printer: object, cycle: bool) -> None:  # hypothesis's printer uses this
        printer.text(str(self))  # type: ignore[attr-defined]


def _chance(draw: st.DrawFn, n: int) -> bool:
    """True with probability about 1/n; False is hypothesis's simplest value, so shrinking removes it."""
    return draw(st.sampled_from(range(n))) == n - 1


def _fmt(x: float) -> str:
    return f"{x:g}"


def _bound_text(b: Bound) -> str:
    return f"[{_fmt(b[0])},{_fmt(b[1])}]"


CRISP = ((1.0, 1.0),) * 3 + ((0.0, 0.0),)  # what a crisp program sets (binding: not [0,1])


@st.composite
def bounds(draw: st.DrawFn, binding: bool | None = None, crisp: bool = False) -> Bound:
    """A bound from the grid, mostly [1,1], [0,0] or a half so that rules actually fire. binding=True
    excludes [0,1]; binding=False gives [0,1]. crisp: [1,1], [0,0] (or [0,1] unless binding)."""
    if binding is False:
        return (0.0, 1.0)
    if crisp:
        return draw(st.sampled_from(CRISP if binding else CRISP + ((0.0, 1.0),)))
    common = draw(st.sampled_from(((1.0, 1.0),) * 12 + ((0.0, 0.0),) * 3 + ((0.5, 1.0),) * 2
                                  + ((0.0, 0.5), None, None, None)))
    if common is not None:
        return common
    lo = draw(st.sampled_from(GRID))
    up = draw(st.sampled_from([g for g in GRID if g >= lo]))
    if binding and (lo, up) == (0.0, 1.0):
        return (1.0, 1.0)
    return (lo, up)


@dataclass
class _Sig:
    """The vocabulary of one scenario: predicates with arities, nodes split into components."""
    arity: dict[str, int]
    groups: list[list[str]]

    @property
    def nodes(self) -> list[str]:
        return [n for g in self.groups for n in g]


@st.composite
def signatures(draw: st.DrawFn) -> _Sig:
    n_preds = draw(st.sampled_from((2, 2, 3, 3, 4)))  # few predicates: rules feed each other
    arity = {f"p{i}": draw(st.sampled_from((1, 2))) for i in range(n_preds)}
    n_nodes = draw(st.sampled_from((2, 3, 3, 4, 5)))
    nodes = [f"n{i}" for i in range(n_nodes)]
    # one or two components: binary facts never cross them, so joins that mix components are wrong
    cut = draw(st.integers(1, n_nodes))
    groups = [nodes[:cut], nodes[cut:]] if cut < n_nodes else [nodes]
    return _Sig(arity, groups)


@st.composite
def ground_args(draw: st.DrawFn, sig: _Sig, pred: str, nodes: list[str] | None = None) -> tuple[str, ...]:
    if nodes is not None:
        return tuple(draw(st.sampled_from(nodes)) for _ in range(sig.arity[pred]))
    group = draw(st.sampled_from(sig.groups))
    return tuple(draw(st.sampled_from(group)) for _ in range(sig.arity[pred]))


@st.composite
def fact_lines(draw: st.DrawFn, sig: _Sig, steps: int, crisp: bool = False) -> str:
    pred = draw(st.sampled_from(sorted(sig.arity)))
    args = draw(ground_args(sig, pred))
    neg = "~" if _chance(draw, 10) else ""
    b = draw(bounds(binding=True, crisp=crisp))
    static = _chance(draw, 7)
    kinds = ("none", "at", "window", "window") if not static else ("none", "at")
    kind = draw(st.sampled_from(kinds))
    window = ""
    if kind == "at":
        window = f" @{draw(st.integers(0, steps - 1))}"
    elif kind == "window":
        a = draw(st.sampled_from((0, 0, *range(steps))))
        window = f" @{a}..{draw(st.sampled_from((steps, *range(a, steps + 1))))}"
    return f"{neg}{pred}({','.join(args)}):{_bound_text(b)}{window}{' static' if static else ''}"


def _span(lower, upper, weights) -> tuple[float, float]:
    """A user annotation function for random programs: the hull of the weighted atoms' bounds."""
    keep = weights > 0
    return (float(lower[keep].min()), float(upper[keep].max())) if keep.any() else (0.0, 1.0)


register_annotation("test_span", _span)  # random programs run user functions too (the kernel's pauses)
ANNOTATION_FUNCTIONS = ("average", "weighted_average", "min", "max", "average_lower", "test_span")


@st.composite
def quantifiers(draw: st.DrawFn) -> str:
    """A quantifier prefix: a comparison with a count or a percentage, or forall; total or available."""
    if _chance(draw, 5):
        count = "forall"
    else:
        op = draw(st.sampled_from((">=", ">", "<=", "<", "==")))
        n = draw(st.sampled_from(("0", "1", "2", "3", "0%", "25%", "50%", "50%", "100%", "33.3%")))
        count = f"{op} {n}"
    word = draw(st.sampled_from(("", "", " total", " available")))
    return f"[{count}{word}] "


def _enumerates(pred: str, negated: bool, b: Bound, closed: tuple[str, ...]) -> bool:
    """Whether a clause binds its variables (engine/program.py clause_binds; %closed changes it)."""
    return clause_binds(Literal(pred, (), b[0], b[1], negated), pred in closed)


RULE_OPTIONS = ((), (), (), ("override",), ("intersection",), ("set_static",), ("override", "set_static"),
                ("infer_edges",), ("set_static", "infer_edges"))


@st.composite
def rule_lines(draw: st.DrawFn, sig: _Sig, name: str, heads: list[tuple[str, bool, Bound]],
               crisp: bool = False, aggregates: bool = False, closed: tuple[str, ...] = ()) -> str:
    """One safe rule. `heads` holds the (pred, negated, bound) of earlier rules' heads; the first clause
    often tests one of them, so that rules chain within a step (passes 2, 3, ...). Appends its own head.
    aggregates: some rules get quantified clauses and annotation functions (never immediate ones).
    `closed`: the %closed predicates (their clauses that [0,0] satisfies do not bind)."""
    preds = sorted(sig.arity)
    n_body = draw(st.integers(1, 3))
    clauses: list[tuple[str, list[str], bool, Bound]] = []  # pred, args (vars upper-case), negated, bound
    used: list[str] = []
    if heads and not _chance(draw, 3):
        pred, negated, b = draw(st.sampled_from(heads))
        args = list(VARIABLES[: sig.arity[pred]])
        used += args
        clauses.append((pred, args, negated, b if b != (0.0, 1.0) else (1.0, 1.0)))
    for i in range(len(clauses), n_body):
        pred = draw(st.sampled_from(preds))
        args = []
        for _ in range(sig.arity[pred]):
            if _chance(draw, 8):
                args.append(draw(st.sampled_from(sig.nodes)))
            elif used and not _chance(draw, 3):  # mostly reuse a variable: joins, not cross products
                args.append(draw(st.sampled_from(used)))
            else:
                args.append(draw(st.sampled_from(VARIABLES)))
            if args[-1][0].isupper() and args[-1] not in used:
                used.append(args[-1])
        negated = _chance(draw, 7)
        b = draw(bounds(binding=True if i == 0 else draw(st.sampled_from((True, True, True, False)))))
        clauses.append((pred, args, negated, b))
    # safety: a variable of a non-binding clause ([0,1], or one [0,0] satisfies on a closed predicate) or
    # of the head must occur in a binding clause
    bound_vars = sorted({a for p, args, n, b in clauses if _enumerates(p, n, b, closed)
                         for a in args if a[0].isupper()})
    fixed = []
    for pred, args, negated, b in clauses:
        if not _enumerates(pred, negated, b, closed):
            args = [a if not a[0].isupper() or a in bound_vars
                    else (draw(st.sampled_from(bound_vars)) if bound_vars else draw(st.sampled_from(sig.nodes)))
                    for a in args]
        fixed.append((pred, args, negated, b))
    # mostly a predicate the body does not test: rules then feed each other instead of themselves
    others = [p for p in preds if p not in {c[0] for c in fixed}]
    head_pred = draw(st.sampled_from(others if others and not _chance(draw, 4) else preds))
    head_args = [draw(st.sampled_from(bound_vars)) if bound_vars and not _chance(draw, 6)
                 else draw(st.sampled_from(sig.nodes)) for _ in range(sig.arity[head_pred])]
    head_neg = "~" if _chance(draw, 8) else ""
    head_bound = draw(bounds(crisp=crisp))
    delay = draw(st.sampled_from((0, 0, 1, 2)))
    # quantified clauses: ones whose variables other binding clauses bind (their candidates come from them)
    prefixes = [""] * len(fixed)
    annotation = ""
    if aggregates and not _chance(draw, 3):
        for i in range(1, len(fixed)):
            others = {a for j, (p, args, n, b) in enumerate(fixed) if j != i and prefixes[j] == "" and
                      _enumerates(p, n, b, closed) for a in args if a[0].isupper()}
            if all(a in others for a in fixed[i][1] if a[0].isupper()) and not _chance(draw, 3):
                prefixes[i] = draw(quantifiers())
        while any(prefixes):  # safe: head, [0,1] and quantified clauses' variables bound by the others
            unq = {a for j, (p, args, n, b) in enumerate(fixed) if not prefixes[j] and _enumerates(p, n, b, closed)
                   for a in args if a[0].isupper()}
            needed = {a for a in head_args if a[0].isupper()} | {
                a for j, (p, args, n, b) in enumerate(fixed) if prefixes[j] or not _enumerates(p, n, b, closed)
                for a in args if a[0].isupper()}
            if needed <= unq:
                break
            prefixes[max(j for j, q in enumerate(prefixes) if q)] = ""
        if _chance(draw, 2):
            annotation = draw(st.sampled_from(ANNOTATION_FUNCTIONS))
    aggregated = annotation != "" or any(prefixes)
    arrow = "<-!" if delay == 0 and not aggregated and _chance(draw, 3) else f"<-{delay}"
    options = list(draw(st.sampled_from(RULE_OPTIONS)))
    if annotation and _chance(draw, 2):
        options.append("weights=" + ",".join(draw(st.sampled_from(("0", "1", "2", "0.5")))
                                            for _ in fixed))
    option = f" {{{', '.join(options)}}}" if options else ""
    heads.append((head_pred, bool(head_neg), head_bound))
    body = ", ".join(f"{q}{'~' if n else ''}{p}({','.join(a)}):{_bound_text(b)}"
                     for q, (p, a, n, b) in zip(prefixes, fixed))
    head_annotation = annotation or _bound_text(head_bound)
    return (f"{name}: {head_neg}{head_pred}({','.join(head_args)}):{head_annotation} {arrow} {body}"
            f"{option}")


@st.composite
def ext_facts(draw: st.DrawFn, sig: _Sig, nodes: list[str], max_per_step: int = 3,
              crisp: bool = False) -> list[ExtFact]:
    out = []
    for _ in range(draw(st.integers(0, max_per_step))):
        pred = draw(st.sampled_from(sorted(sig.arity)))
        args = draw(ground_args(sig, pred, nodes))
        lo, up = draw(bounds(binding=True, crisp=crisp))
        out.append(ExtFact(pred, args, lo, up, _chance(draw, 10)))
    return out


def graph_of(nodes: list[str], facts: list[tuple[str, tuple[str, ...], Bound]],
             edges: list[tuple[str, str]]) -> Graph:
    """A Graph (columns, as load_graphml makes them) with these nodes (fact nodes appended), static facts
    at t = 0 and edges."""
    nodes = list(dict.fromkeys([*nodes, *(a for _, args, _ in facts for a in args)]))
    ids = {n: i for i, n in enumerate(nodes)}
    labels = list(dict.fromkeys(p for p, _, _ in facts))
    arity = [next(len(a) for p, a, _ in facts if p == lab) for lab in labels]
    return Graph(nodes, labels, arity,
                 np.array([labels.index(p) for p, _, _ in facts], np.int32),
                 np.array([(ids[a[0]], ids[a[1]] if len(a) > 1 else -1) for _, a, _ in facts], np.int32).reshape(-1, 2),
                 np.array([b for _, _, b in facts], np.float64).reshape(-1, 2),
                 edges=np.array([(ids[a], ids[b]) for a, b in edges], np.int32).reshape(-1, 2))


@st.composite
def scenarios(draw: st.DrawFn, per_world: int = 0, with_graph: bool = True,
              policies: tuple[str, ...] = POLICIES, crisp: bool = False, aggregates: bool = False) -> Scenario:
    """A parsed random program plus, per step, external facts for every world (or, with per_world=W,
    separate external facts for each of W worlds). The policy is drawn from `policies`. crisp: every
    rule head, fact and external fact sets [0,0], [1,1] or [0,1] (body clauses still test any bound)."""
    sig = draw(signatures())
    steps = draw(st.integers(2, 4))
    lines = [f"%mode {draw(st.sampled_from(('intersection', 'override')))}",
             f"%timesteps {draw(st.sampled_from(('persistent', 'reset')))}",
             f"%inconsistency {draw(st.sampled_from(policies))}",
             f"%edge_heads {draw(st.sampled_from(('any', 'any', 'graph')))}"]
    closed = tuple(p for p in sorted(sig.arity) if _chance(draw, 3))
    if closed:
        lines.append(f"%closed {', '.join(closed)}")
    # a base of facts that hold at every step, so that bodies (joins included) find matches
    for pred in sorted(sig.arity):
        for args in draw(st.lists(ground_args(sig, pred), max_size=3, unique=True)):
            lines.append(f"{pred}({','.join(args)}):{_bound_text(draw(bounds(binding=True, crisp=crisp)))}"
                         f" @0..{steps}")
    lines += draw(st.lists(fact_lines(sig, steps, crisp), min_size=1, max_size=8))
    heads: list[tuple[str, bool, Bound]] = []
    lines += [draw(rule_lines(sig, f"r{i}", heads, crisp, aggregates, closed))
              for i in range(draw(st.integers(1, 6)))]
    text = "\n".join(lines) + "\n"

    # a graph: some nodes (possibly isolated), a few static facts at t = 0 on them, a few edges
    graph = Graph()
    if with_graph and draw(st.booleans()):
        nodes = draw(st.lists(st.sampled_from(sig.nodes), unique=True, max_size=3))
        facts: list[tuple[str, tuple[str, ...], Bound]] = []
        for _ in range(draw(st.integers(0, 2))):
            group = draw(st.sampled_from(sig.groups))
            pred = draw(st.sampled_from(sorted(sig.arity)))
            args = tuple(draw(st.sampled_from(group)) for _ in range(sig.arity[pred]))
            facts.append((pred, args, draw(bounds(binding=True, crisp=crisp))))
            if not _chance(draw, 4):  # sometimes a fact's node is missing from the node list
                nodes += [a for a in dict.fromkeys(args) if a not in nodes]
        edges = draw(st.lists(st.tuples(st.sampled_from(sig.nodes), st.sampled_from(sig.nodes)), max_size=4))
        graph = graph_of([*nodes, *(a for e in edges for a in e)], facts, edges)
    program = parse_program(text, "<hypothesis>")
    if per_world:
        # only constants every world already knows: a new node would get different ids in different worlds
        known = list(dict.fromkeys([*graph.nodes, *program.constants()]))
        world_ext = [[draw(ext_facts(sig, known, crisp=crisp)) for _ in range(steps)] for _ in range(per_world)]
        return Scenario(text, program, steps, graph, [[] for _ in range(steps)], world_ext)
    nodes = [*sig.nodes, *FRESH_NODES]
    return Scenario(text, program, steps, graph, [draw(ext_facts(sig, nodes, crisp=crisp)) for _ in range(steps)])


# ---- TOML values of every kind, as text: a spec key given a value of the wrong type --------------------

_TOML_SCALARS = st.one_of(
    st.integers(-3, 10**6).map(str), st.sampled_from(["true", "false", "1.5", "-0.0", "nan", "inf", "1e400"]),
    st.sampled_from(["1979-05-27", "07:32:00", "1979-05-27T07:32:00Z"]),
    st.sampled_from(['""', '"x"', '"c0_0"', '"at(C)"', '"1 +"', '"[1, 2]"', '"a\\u0000b"', '"cells"', '"{}"',
                     "'p(X'", '"~at(C)"', '"at(c0_0):[0.5,1]"', '"len"', '"goal_reward"']),
)


def toml_values() -> st.SearchStrategy[str]:
    """TOML value texts of any type: numbers, booleans, dates, strings (atoms, expressions, a NUL),
    arrays and inline tables of them, nested."""
    return st.recursive(_TOML_SCALARS, lambda inner: st.one_of(
        st.lists(inner, max_size=3).map(lambda xs: f"[{', '.join(xs)}]"),
        st.lists(st.tuples(st.sampled_from(["a", "x", "G", "name"]), inner), max_size=2, unique_by=lambda kv: kv[0])
        .map(lambda kvs: "{" + ", ".join(f"{k} = {v}" for k, v in kvs) + "}")), max_leaves=6)
