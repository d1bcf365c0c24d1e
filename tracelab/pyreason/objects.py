"""PyReason's user-facing objects with its constructors: `Rule`, `Fact`, `Query`, `Threshold` and the
closed interval `closed(lower, upper)` that `filter_and_sort_nodes(bound=...)` takes. Each parses its
text when it is made, as PyReason's do, so a mistake is raised where the user wrote it (a located
RuleSyntaxError, one line). The parsing is the file readers' (rules.py, facts.py, text.py)."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from tracelab.engine.errors import RuleSyntaxError
from tracelab.engine.program import SourceLoc

from . import rules as _rules
from .facts import PFact, parse_fact
from .rules import PRule, parse_rule
from .text import PLiteral, Squeezed, parse_literal


@dataclass(frozen=True)
class Interval:
    """A closed interval [lower, upper] (PyReason's `interval.closed`); `a in b` is containment."""
    lower: float
    upper: float

    def __contains__(self, other: object) -> bool:
        lo, up = _pair(other)
        return self.lower <= lo and up <= self.upper


def closed(lower: float, upper: float) -> Any:
    """PyReason's `interval.closed(l, u)`: an interval compiled functions can read (an annotation
    function's bounds, numba_interval.py; compiling its constructor the first time in a process)."""
    from .numba_interval import NumbaInterval
    return NumbaInterval(lower, upper)


def _pair(bound: object) -> tuple[float, float]:
    """(lower, upper) of an Interval, a closed() interval or a pair."""
    if hasattr(bound, "lower") and hasattr(bound, "upper"):
        return float(bound.lower), float(bound.upper)  # type: ignore[attr-defined]
    lo, up = bound  # type: ignore[misc]
    return float(lo), float(up)


def Threshold(quantifier: str, quantifier_type: Sequence[str], thresh: float) -> _rules.Threshold:  # noqa: N802
    """PyReason's `Threshold("greater_equal", ("number", "total"), 1)`: a clause's quantifier."""
    if quantifier not in _rules.QUANTIFIERS:
        raise ValueError(f"Threshold: invalid quantifier {quantifier!r} (one of {', '.join(_rules.QUANTIFIERS)})")
    if len(quantifier_type) != 2 or quantifier_type[0] not in ("number", "percent") \
            or quantifier_type[1] not in ("total", "available"):
        raise ValueError(f"Threshold: invalid quantifier type {tuple(quantifier_type)!r} "
                         "((number|percent, total|available))")
    return _rules.Threshold(quantifier, quantifier_type[0], quantifier_type[1], thresh)


class Rule:
    """PyReason's `Rule(rule_text, name=None, infer_edges=False, set_static=False, custom_thresholds=None,
    weights=None)`. `custom_thresholds` is a list (one per body clause) or a dict {clause index:
    threshold}; `weights` one number >= 0 per body clause."""

    def __init__(self, rule_text: str, name: str | None = None, infer_edges: bool = False, set_static: bool = False,
                 custom_thresholds: Sequence[_rules.Threshold] | Mapping[int, _rules.Threshold] | None = None,
                 weights: Sequence[float] | None = None) -> None:
        where = SourceLoc(f"<Rule {name or rule_text!r}>", 1, 1)
        self.rule: PRule = parse_rule(rule_text, name or "", where, rule_text)
        self.rule.infer_edges = bool(infer_edges)
        self.rule.set_static = bool(set_static)
        n = len(self.rule.body)
        if custom_thresholds is not None:
            items = custom_thresholds.items() if isinstance(custom_thresholds, Mapping) else \
                enumerate(custom_thresholds)
            if not isinstance(custom_thresholds, Mapping) and len(custom_thresholds) != n:
                raise _error(where, rule_text, f"{len(custom_thresholds)} custom thresholds for {n} body clauses")
            for i, t in items:
                if not 0 <= int(i) < n or not isinstance(t, _rules.Threshold):
                    raise _error(where, rule_text, f"custom_thresholds[{i!r}] is not a Threshold of a clause "
                                                   f"(0..{n - 1})")
                self.rule.thresholds[int(i)] = t
        if weights is not None:
            w = [float(x) for x in weights]
            if len(w) != n or any(x < 0 for x in w):
                raise _error(where, rule_text, f"weights must be {n} numbers >= 0, one per body clause")
            self.rule.weights = w

    @classmethod
    def from_parsed(cls, rule: PRule) -> "Rule":
        """A rule read from a file (rules.py) as a pr.Rule."""
        made = cls.__new__(cls)
        made.rule = rule
        return made

    def get_rule_name(self) -> str | None:
        return self.rule.name or None

    def set_rule_name(self, name: str) -> None:
        self.rule.name = name

    def __repr__(self) -> str:
        return f"Rule({self.rule.text!r}, {self.get_rule_name()!r})"


class Fact:
    """PyReason's `Fact(fact_text, name=None, start_time=0, end_time=0, static=False)`: both times
    included; `static` sets it at t = 0 for good."""

    def __init__(self, fact_text: str, name: str | None = None, start_time: int = 0, end_time: int = 0,
                 static: bool = False) -> None:
        where = SourceLoc(f"<Fact {name or fact_text!r}>", 1, 1)
        self.literal: PLiteral = parse_fact(fact_text, where, fact_text)
        if int(start_time) < 0 or (int(end_time) < int(start_time) and not static):
            raise _error(where, fact_text, f"the times {start_time}..{end_time} are not a window (0 <= start <= end)")
        self.name = name
        self.start_time = int(start_time)
        self.end_time = int(end_time)
        self.static = bool(static)
        self.type = "node" if len(self.literal.args) == 1 else "edge"

    @property
    def pred(self) -> str:
        """PyReason's `fact.pred`: the predicate as its parser reads it (spaces deleted)."""
        return self.literal.pred

    @property
    def component(self) -> str | tuple[str, ...]:
        """PyReason's `fact.component`: the node, or the (source, target) edge."""
        args = tuple(self.literal.args)
        return args[0] if len(args) == 1 else args

    @classmethod
    def from_parsed(cls, fact: PFact) -> "Fact":
        """A fact read from a file (facts.py) as a pr.Fact."""
        made = cls.__new__(cls)
        made.literal, made.name, made.start_time, made.end_time, made.static = \
            fact.literal, fact.name, fact.start, fact.end, fact.static
        made.type = "node" if len(fact.literal.args) == 1 else "edge"
        return made

    def __str__(self) -> str:
        lit = self.literal
        when = " | static" if self.static else f" | start: {self.start_time} -> end: {self.end_time}"
        return f"{lit.pred}({','.join(lit.args)}) : [{lit.lower},{lit.upper}]{when}"


class Query:
    """PyReason's `Query('pred(node)')`, `Query('pred(a,b) : [l,u]')`, `Query('~pred(node)')`: an atom
    and a bound ([1,1] by default); it holds when the atom's bound lies inside it."""

    def __init__(self, query_text: str) -> None:
        sq = Squeezed(query_text, SourceLoc("<Query>", 1, 1))
        self.literal: PLiteral = parse_literal(sq, 0, len(sq.s), "query")
        self.query_text = query_text

    def get_predicate(self) -> str:
        return self.literal.pred

    def get_component(self) -> str | tuple[str, str]:
        args = self.literal.args
        return args[0] if len(args) == 1 else (args[0], args[1])

    def get_component_type(self) -> str:
        return "node" if len(self.literal.args) == 1 else "edge"

    def get_bounds(self) -> Interval:
        return Interval(self.literal.lower, self.literal.upper)

    def __str__(self) -> str:
        return self.query_text

    __repr__ = __str__


def _error(where: SourceLoc, text: str, message: str) -> RuleSyntaxError:
    return RuleSyntaxError(message, where.file, where.line, where.column, text)
