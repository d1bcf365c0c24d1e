"""PyReason's rule filtering by queries (`reason(queries=...)`, `ruleset_filter.filter_ruleset`): the rules
that can derive a queried predicate, and the rules that can derive their body predicates, transitively.
PyReason walks this recursively without remembering what it visited (a recursive rule loops); here each
predicate is visited once, which gives the same rules and ends."""
from __future__ import annotations

from collections.abc import Sequence

from .objects import Query, Rule


def filter_ruleset(queries: Sequence[Query], rules: Sequence[Rule]) -> list[Rule]:
    """The rules (in their order) whose head predicate a query needs, directly or through bodies."""
    wanted = [q.get_predicate() for q in queries]
    needed: set[str] = set()
    while wanted:
        pred = wanted.pop()
        if pred in needed:
            continue
        needed.add(pred)
        for r in rules:
            if r.rule.head.pred == pred:
                wanted.extend(c.pred for c in r.rule.body)
    return [r for r in rules if r.rule.head.pred in needed]
