"""The reference evaluator: docs/language.md executed naively, in plain Python, one world.

It exists to be obviously correct, not fast: groundings are found by trying every assignment of a rule's
variables over every node, and every pass re-evaluates every rule from scratch. The compiled engine
(engine/core.py, engine/kernel.py) must agree with it; tests/test_engine_vs_reference.py checks that.
"""
from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from . import annotations, head_functions
from .cause_kinds import CAUSE_EXTERNAL, CAUSE_FACT, CAUSE_POLICY, CAUSE_RESET, CAUSE_RULE
from .errors import FixpointError, InconsistencyError, ProgramError
from .program import (
    EPS,
    INCONSISTENCY_POLICIES,
    Fact,
    Literal,
    Program,
    Quantifier,
    Rule,
    Term,
    constant_text,
    ordered_nodes,
)

Atom = tuple[str, tuple[str, ...]]
Interval = tuple[float, float]

FULL: Interval = (0.0, 1.0)


@dataclass(frozen=True)
class RefChange:
    """One trace row. `grounding` holds the variable values (rule.variables order) of the rule grounding
    the row names, None for other causes; `grounding_rule` is that grounding's rule index (for a rule row it
    equals cause_id, for a policy row it says which rule the first incoming grounding belongs to)."""
    t: int
    pass_no: int
    atom: Atom
    old: Interval
    new: Interval
    cause_kind: int
    cause_id: int
    grounding: tuple[str, ...] | None
    n_sources: int
    grounding_rule: int | None = None


@dataclass(frozen=True)
class _Source:
    mu: Interval
    override: bool
    kind: int  # CAUSE_FACT, CAUSE_EXTERNAL or CAUSE_RULE
    cid: int  # fact index, external fact index or rule index
    grounding: tuple[str, ...] | None = None
    grounding_ids: tuple[int, ...] = ()  # node ids of the grounding: the source-order key among firings
    freeze: bool = False  # a firing of a `{set_static}` rule: the atom is static after this update


@dataclass(frozen=True)
class _External:
    atom: Atom
    mu: Interval
    static: bool
    t: int


def atom_text(atom: Atom) -> str:
    """`pred(a,b)`: the text the engine uses for an atom."""
    return f"{atom[0]}({','.join(map(constant_text, atom[1]))})"


def _fmt(iv: Interval) -> str:
    return f"[{iv[0]:g},{iv[1]:g}]"


def _meet(a: Interval | None, b: Interval | None) -> Interval | None:
    """Intersection of two intervals, None when empty (or when either is already empty). Empty means
    lower > upper + EPS: the same tolerance as containment (docs/language.md "Interpretation")."""
    if a is None or b is None:
        return None
    lo, up = max(a[0], b[0]), min(a[1], b[1])
    return (lo, up) if lo <= up + EPS else None


def _meet_all(mus: Sequence[Interval]) -> Interval | None:
    acc: Interval | None = FULL
    for mu in mus:
        acc = _meet(acc, mu)
    return acc


def _effective(lower: float, upper: float, negated: bool) -> Interval:
    """The interval a literal tests or sets on its atom: `~p:[l,u]` speaks of p as [1-u, 1-l]."""
    return (1.0 - upper, 1.0 - lower) if negated else (lower, upper)


class ReferenceEvaluator:
    """One world of `program` over `graph_nodes` (plus the program's constants), stepped like Engine."""

    def __init__(self, program: Program, graph_nodes: Sequence[str] = (), graph_facts: Sequence[Fact] = (),
                 max_passes: int = 1000, max_immediate: int = 100000,
                 graph_edges: Sequence[tuple[str, str]] = ()) -> None:
        self.program = program
        self.closed = frozenset(program.closed)
        # the graph's edges (source, target): where `%edge_heads graph` lets edge heads of rules without
        # {infer_edges} land
        self.edges = frozenset((a, b) for a, b in graph_edges)
        self.rules: list[Rule] = list(program.rules)
        # graph facts come first: fact ids 0..g-1, program facts g.. (docs/language.md "Source order")
        self.facts: list[Fact] = [*graph_facts, *program.facts]
        self.nodes: list[str] = ordered_nodes(program, list(graph_nodes))
        for f in graph_facts:  # a graph fact's constant missing from graph_nodes comes after the program's
            for term in f.literal.args:
                if term.name not in self.nodes:
                    self.nodes.append(term.name)
        self.max_passes = max_passes
        self.max_immediate = max_immediate
        self.t = 0
        self.changes: list[RefChange] = []
        self._interp: dict[Atom, Interval] = {}  # atoms absent here are [0,1]
        self._static: set[Atom] = set()
        self._last_cause: dict[Atom, tuple[int, int, tuple[str, ...] | None, int | None]] = {}
        self._externals: list[_External] = []
        self._scheduled: dict[int, list[_Source]] = {}  # due time -> firings of delayed rules

    # ---- input / output ----

    def add_fact(self, pred: str, args: tuple[str, ...], lower: float, upper: float,
                 static: bool = False) -> None:
        """An external fact: a source at pass 0 of the next step (self.t)."""
        for a in args:
            if a not in self.nodes:
                self.nodes.append(a)  # new constants become nodes in order of arrival
        self._externals.append(_External((pred, tuple(args)), (lower, upper), static, self.t))

    def bound(self, atom: Atom) -> Interval:
        return self._interp.get(atom, FULL)

    def interpretation(self) -> dict[Atom, Interval]:
        """Every atom whose interval is not [0,1]."""
        return {a: iv for a, iv in self._interp.items() if iv != FULL}

    def is_static(self, atom: Atom) -> bool:
        return atom in self._static

    # ---- satisfaction and groundings ----

    def _holds(self, lit: Literal, binding: dict[str, str]) -> bool:
        """I ⊨ lit: the atom's interval (complemented for `~`) is contained in the literal's bound.
        EPS is the shared tolerance of engine/program.py (1 - x is not exact in binary)."""
        return self._atom_holds(self._ground(lit, binding), lit)

    def _read(self, atom: Atom) -> Interval:
        """The atom's interval as body clauses read it: on a %closed predicate, an atom nothing set
        ([0,1]) reads as [0,0]."""
        iv = self.bound(atom)
        return (0.0, 0.0) if atom[0] in self.closed and iv == FULL else iv

    def _atom_holds(self, atom: Atom, lit: Literal) -> bool:
        a, b = _effective(*self._read(atom), lit.negated)
        return a >= lit.lower - EPS and b <= lit.upper + EPS

    def _ground(self, lit: Literal, binding: dict[str, str]) -> Atom:
        return (lit.pred, tuple(binding[t.name] if t.is_var else t.name if t.function is None
                                else self._called(t, binding) for t in lit.args))

    def _called(self, term: Term, binding: dict[str, str]) -> str:
        """A head function call's node (docs/language.md "Head functions"), one that exists."""
        args = tuple(binding[a.name] if a.is_var else a.name for a in term.call_args)
        try:
            name = head_functions.call(head_functions.bind(term), term, args, term.name)
        except head_functions.HeadFunctionError as e:
            raise ProgramError(str(e), "<reference>") from None
        if name not in self.nodes:
            raise ProgramError(f"head function '{term.function}' returned {name!r}, which is not a node",
                               "<reference>")
        return name

    def _active_groundings(self, rule: Rule) -> list[tuple[tuple[int, ...], tuple[str, ...], Atom]]:
        """Every assignment of rule.variables over all nodes whose body holds, smallest node ids first
        (itertools.product enumerates in lexicographic order): (node ids, values, head atom)."""
        variables = rule.variables
        on_edges = self._on_graph_edges(rule)
        out = []
        for ids in itertools.product(range(len(self.nodes)), repeat=len(variables)):
            values = tuple(self.nodes[i] for i in ids)
            binding = dict(zip(variables, values))
            if all(self._holds(lit, binding) for lit in rule.body):
                head = self._ground(rule.head, binding)
                if on_edges and head[1] not in self.edges:
                    continue  # %edge_heads graph: this rule's head stays on the graph's edges
                out.append((ids, values, head))
        return out

    def _rule_firings(self, ri: int) -> list[tuple[Atom, _Source]]:
        """The firings of rule ri on the current interpretation, in source order: one per active grounding,
        or one per head grounding for a rule with quantifiers or an annotation function."""
        if self.rules[ri].aggregated:
            return self._aggregated_firings(ri)
        return [(head, self._firing(ri, ids, values)) for ids, values, head in self._active_groundings(self.rules[ri])]

    def _aggregated_firings(self, ri: int) -> list[tuple[Atom, _Source]]:
        """docs/language.md "Quantifiers" and "Annotation functions": the joins of the unquantified clauses
        grouped by head grounding; a group fires when every quantifier holds over its candidates, named by
        its first join whose quantified clauses hold (else its first join), with the head's bound or the
        function's result."""
        rule = self.rules[ri]
        variables = rule.variables
        on_edges = self._on_graph_edges(rule)
        unquantified = [lit for i, lit in enumerate(rule.body) if rule.quantifier(i) is None]
        groups: dict[Atom, list[tuple[tuple[int, ...], dict[str, str]]]] = {}
        for ids in itertools.product(range(len(self.nodes)), repeat=len(variables)):
            binding = dict(zip(variables, (self.nodes[i] for i in ids)))
            if all(self._holds(lit, binding) for lit in unquantified):
                head = self._ground(rule.head, binding)
                if on_edges and head[1] not in self.edges:
                    continue  # %edge_heads graph: this rule's head stays on the graph's edges
                groups.setdefault(head, []).append((ids, binding))
        out = []
        for head, joins in groups.items():
            if not all(self._quantifier_holds(q, rule.body[ci], [b for _, b in joins])
                       for ci, q in enumerate(rule.quantifiers) if q is not None):
                continue
            mu = self._head_bound(rule, [b for _, b in joins])
            if mu is None:
                continue
            # the firing is named by the first join whose quantified clauses hold too, else the first join
            quantified = [lit for i, lit in enumerate(rule.body) if rule.quantifier(i) is not None]
            ids, binding = next((j for j in joins if all(self._holds(lit, j[1]) for lit in quantified)), joins[0])
            out.append((head, _Source(mu, self._rule_override(rule), CAUSE_RULE, ri,
                                      tuple(binding[v] for v in variables), ids, freeze=rule.set_static)))
        return out

    def _candidates(self, lit: Literal, joins: list[dict[str, str]]) -> list[Atom]:
        """The distinct atoms of a clause over the joins, in join order."""
        return list(dict.fromkeys(self._ground(lit, b) for b in joins))

    def _quantifier_holds(self, q: Quantifier, lit: Literal, joins: list[dict[str, str]]) -> bool:
        cands = self._candidates(lit, joins)
        if q.available:  # only atoms that carry a bound other than [0,1] (also on a %closed predicate)
            cands = [a for a in cands if self.bound(a) != FULL]
        n, d = sum(self._atom_holds(a, lit) for a in cands), len(cands)
        if q.percent:
            if d == 0:
                return False
            lhs, rhs = n * 100.0, q.value * d
        else:
            lhs, rhs = float(n), q.value
        return {">=": lhs >= rhs, ">": lhs > rhs, "<=": lhs <= rhs, "<": lhs < rhs, "==": lhs == rhs}[q.op]

    def _head_bound(self, rule: Rule, joins: list[dict[str, str]]) -> Interval | None:
        """The head's bound, or the annotation function of the atoms that counted: per clause, in clause
        order, its distinct atoms that hold (None: the function gives no bound)."""
        head = rule.head
        if rule.annotation is None:
            return _effective(head.lower, head.upper, head.negated)
        lower, upper, weights = [], [], []
        for ci, lit in enumerate(rule.body):
            for atom in self._candidates(lit, joins):
                if self._atom_holds(atom, lit):
                    lo, up = self._read(atom)
                    lower.append(lo)
                    upper.append(up)
                    weights.append(rule.weights[ci] if rule.weights else 1.0)
        if not lower:
            return None
        args = (np.array(lower), np.array(upper), np.array(weights))
        if rule.annotation in annotations.BUILTINS:
            res = annotations.lookup(rule.annotation)(*args)
        else:
            res = annotations.call_user(rule.annotation, annotations.lookup(rule.annotation), rule.name, *args)
        if res is None:
            return None
        return _effective(res[0], res[1], head.negated)

    def _on_graph_edges(self, rule: Rule) -> bool:
        """Whether the rule's groundings are limited to heads on the graph's edges (docs/language.md)."""
        return (self.program.edge_heads == "graph" and len(rule.head.args) == 2 and not rule.infer_edges)

    def _rule_override(self, rule: Rule) -> bool:
        return (rule.mode or self.program.mode) == "override"

    def _firing(self, ri: int, ids: tuple[int, ...], values: tuple[str, ...]) -> _Source:
        rule = self.rules[ri]
        head = rule.head
        return _Source(_effective(head.lower, head.upper, head.negated), self._rule_override(rule),
                       CAUSE_RULE, ri, values, ids, freeze=rule.set_static)

    # ---- updating an atom (docs/language.md "Updating an atom") ----

    def _resolve(self, atom: Atom, sources: Sequence[_Source]) -> tuple[Interval, bool]:
        """The new interval of `atom` under the set `sources` (in source order) and whether the update was
        inconsistent. Pure: does not touch the state. Under `abort` an inconsistent update returns the old
        interval with inconsistent=True; the caller raises."""
        cur = self.bound(atom)
        over = [s.mu for s in sources if s.override]
        inter = [s.mu for s in sources if not s.override]
        mo = _meet_all(over)
        mi = _meet_all(inter)
        base = mo if over else cur
        result = _meet(base, mi)
        if mo is not None and mi is not None and result is not None:
            return result, False
        policy = self.program.inconsistency
        if policy == "reset_freeze":
            return FULL, True
        if policy == "keep_old" or policy == "abort":
            return cur, True
        if policy == "take_new":
            new = _meet(mo, mi)
            return (new if new is not None else sources[-1].mu), True
        if policy == "hull":
            ivs = [cur, *(s.mu for s in sources)]
            return (min(iv[0] for iv in ivs), max(iv[1] for iv in ivs)), True
        raise ValueError(f"unknown inconsistency policy {policy!r}")

    def _would_change(self, atom: Atom, source: _Source) -> bool:
        """Whether applying the single source would change the atom (an abort counts: applying raises)."""
        if atom in self._static:
            return False
        if source.freeze:
            return True  # a {set_static} firing changes the atom's static flag
        new, inconsistent = self._resolve(atom, [source])
        if inconsistent and self.program.inconsistency == "abort":
            return True
        return new != self.bound(atom)

    def _apply(self, atom: Atom, sources: Sequence[_Source], t: int, pass_no: int) -> bool:
        """Apply the set `sources` (already in source order) to `atom`; log a row if it changes.
        Returns whether the interval changed."""
        if atom in self._static:
            return False  # updates to a static atom are ignored
        old = self.bound(atom)
        new, inconsistent = self._resolve(atom, sources)
        policy = self.program.inconsistency
        if inconsistent and policy == "abort":
            raise InconsistencyError(self._abort_message(atom, t, sources[0]))
        if (inconsistent and policy == "reset_freeze") or any(s.freeze for s in sources):
            self._static.add(atom)  # frozen even when its interval does not change
        if new == old:
            return False
        if inconsistent:
            first_rule = next((s for s in sources if s.kind == CAUSE_RULE), None)
            cause = (CAUSE_POLICY, INCONSISTENCY_POLICIES.index(policy),
                     first_rule.grounding if first_rule else None, first_rule.cid if first_rule else None)
        else:
            first = sources[0]  # a row names the first source in source order
            cause = (first.kind, first.cid, first.grounding, first.cid if first.kind == CAUSE_RULE else None)
        self._set(atom, new)
        self._last_cause[atom] = cause
        self.changes.append(RefChange(t, pass_no, atom, old, new, cause[0], cause[1], cause[2],
                                      len(sources), cause[3]))
        return True

    def _set(self, atom: Atom, iv: Interval) -> None:
        if iv == FULL:
            self._interp.pop(atom, None)
        else:
            self._interp[atom] = iv

    def _describe(self, kind: int, cid: int, grounding: tuple[str, ...] | None, rule: int | None) -> str:
        if kind == CAUSE_FACT:
            f = self.facts[cid]
            return f"fact {f.name} (#{cid}: {f.literal})"
        if kind == CAUSE_EXTERNAL:
            return f"external fact #{cid}"
        if kind == CAUSE_RULE:
            r = self.rules[cid]
            binding = ", ".join(f"{v}={x}" for v, x in zip(r.variables, grounding or ()))
            return f"rule {r.name} with {binding or 'no variables'}"
        if kind == CAUSE_POLICY:
            text = f"inconsistency policy {INCONSISTENCY_POLICIES[cid]}"
            if rule is not None:
                text += f" (first incoming: {self._describe(CAUSE_RULE, rule, grounding, rule)})"
            return text
        if kind == CAUSE_RESET:
            return "the reset at the start of the step"
        return "nothing (the atom was never set)"

    def _abort_message(self, atom: Atom, t: int, incoming: _Source) -> str:
        old = self.bound(atom)
        old_src = self._describe(*self._last_cause.get(atom, (-1, -1, None, None)))
        new_src = self._describe(incoming.kind, incoming.cid, incoming.grounding, incoming.cid)
        return (f"inconsistent bounds for {atom_text(atom)} at t={t}: its bound {_fmt(old)} came from "
                f"{old_src}; the incoming bound {_fmt(incoming.mu)} from {new_src} cannot be combined with it")

    # ---- one timestep (docs/language.md "One timestep t") ----

    def step(self) -> None:
        t = self.t
        # 1. start: under %timesteps reset every non-static set atom goes back to [0,1]
        if t > 0 and self.program.timesteps == "reset":
            for atom in sorted(self._interp):
                if atom not in self._static:
                    old = self._interp.pop(atom)
                    self._last_cause[atom] = (CAUSE_RESET, -1, None, None)
                    self.changes.append(RefChange(t, 0, atom, old, FULL, CAUSE_RESET, -1, None, 0))

        # 2. pass 0: facts, external facts and scheduled firings, one set of sources per atom
        mode_override = self.program.mode == "override"
        pass0: dict[Atom, list[_Source]] = {}
        becomes_static: list[Atom] = []
        for i, f in enumerate(self.facts):
            if f.start <= t <= f.end:
                atom = self._ground(f.literal, {})
                lit = f.literal
                pass0.setdefault(atom, []).append(
                    _Source(_effective(lit.lower, lit.upper, lit.negated), mode_override, CAUSE_FACT, i))
                if f.static:
                    becomes_static.append(atom)
        for i, e in enumerate(self._externals):
            if e.t == t:
                pass0.setdefault(e.atom, []).append(_Source(e.mu, mode_override, CAUSE_EXTERNAL, i))
                if e.static:
                    becomes_static.append(e.atom)
        firings = sorted(self._scheduled.pop(t, []), key=lambda s: (s.cid, s.grounding_ids))
        for s in firings:
            atom = self._ground(self.rules[s.cid].head, dict(zip(self.rules[s.cid].variables, s.grounding)))
            pass0.setdefault(atom, []).append(s)
        for atom, sources in pass0.items():
            self._apply(atom, sources, t, 0)
        self._static.update(becomes_static)  # a static fact's atom is frozen once the fact is applied

        # 3. fixpoint: immediate phase, then an ordinary pass, until an ordinary pass changes nothing
        immediate = [i for i, r in enumerate(self.rules) if r.immediate]
        ordinary = [i for i, r in enumerate(self.rules) if r.delay == 0 and not r.immediate]
        n_immediate = 0
        k = 0
        changed_last: set[Atom] = set()  # atoms changed by the last pass: named by FixpointError
        while True:
            k += 1
            if k > self.max_passes:
                raise FixpointError(f"no fixpoint at t={t} after {self.max_passes} passes; still changing: "
                                    f"{', '.join(sorted(map(atom_text, changed_last)))}")
            changed_last = set()
            # a. immediate phase: the first grounding (rule index, then node ids) that would change its head
            changed_immediate: set[Atom] = set()
            while True:
                found = None
                for ri in immediate:
                    for ids, values, head in self._active_groundings(self.rules[ri]):
                        src = self._firing(ri, ids, values)
                        if self._would_change(head, src):
                            found = (head, src)
                            break
                    if found:
                        break
                if found is None:
                    break
                n_immediate += 1
                if n_immediate > self.max_immediate:
                    raise FixpointError(
                        f"immediate rules did not settle at t={t} after {self.max_immediate} applications; "
                        f"still changing: {', '.join(sorted(map(atom_text, changed_immediate | {found[0]})))}")
                self._apply(found[0], [found[1]], t, k)
                changed_immediate.add(found[0])
                changed_last.add(found[0])
            # b. ordinary pass: all active groundings read the same interpretation, then apply together
            groups: dict[Atom, list[_Source]] = {}
            for ri in ordinary:  # rule index order, then node ids: source order
                for head, src in self._rule_firings(ri):
                    groups.setdefault(head, []).append(src)
            changed = False
            for atom, sources in groups.items():
                if self._apply(atom, sources, t, k):
                    changed = True
                    changed_last.add(atom)
            if not changed:
                break

        # 4. delayed rules read the final interpretation of t and fire at t + delay
        for ri, rule in enumerate(self.rules):
            if rule.delay > 0:
                for _head, src in self._rule_firings(ri):
                    self._scheduled.setdefault(t + rule.delay, []).append(src)
        self.t += 1

    def run(self, steps: int) -> None:
        for _ in range(steps):
            self.step()
