"""Grounding: every rule grounding that could ever fire, found once by joins over the atoms that can ever
be set (by facts, external facts or rule heads), and kept as integer tables for the kernel.

An atom that nothing can set stays [0,1] forever, and [0,1] satisfies no *binding* clause, so a grounding
needs one settable atom per binding clause. Groundings are full joins: one value per variable across every
clause. New settable atoms (rule heads, external facts on new atoms) are joined semi-naively: each round
only joins that use at least one new atom are made.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .program import EPS, Literal, Rule, effective_bound
from .vocabulary import Vocabulary


@dataclass
class GroundingTable:
    """Rule groundings, by id. Body atoms list every clause of the rule in order (binding or not)."""
    rule: np.ndarray  # int32[G]
    body_ptr: np.ndarray  # int64[G+1]
    body_atoms: np.ndarray  # int32[...]
    var_ptr: np.ndarray  # int64[G+1]
    var_values: np.ndarray  # int32[...] node ids, in Rule.variables order

    def body(self, g: int) -> np.ndarray:
        return self.body_atoms[self.body_ptr[g]:self.body_ptr[g + 1]]

    def values(self, g: int) -> np.ndarray:
        return self.var_values[self.var_ptr[g]:self.var_ptr[g + 1]]


@dataclass
class _CompiledRule:
    index: int
    rule: Rule
    variables: tuple[str, ...]
    head_label: int
    # per clause: label id, args as ("var", index) / ("const", node id)
    clause_labels: list[int]
    clause_args: list[list[tuple[bool, int]]]  # (is_var, var index or node id)
    head_args: list[tuple[bool, int]]
    binding: list[int]  # indices of binding clauses


@dataclass
class Grounder:
    rules: list[Rule]
    vocab: Vocabulary
    # settable atoms, indexed for joins
    settable: set[int] = field(default_factory=set)
    _by_label: dict[int, list[int]] = field(default_factory=dict)
    _by_label_arg: dict[tuple[int, int, int], list[int]] = field(default_factory=dict)
    _new: list[int] = field(default_factory=list)
    _seen: set[tuple[int, tuple[int, ...]]] = field(default_factory=set)
    # growing grounding tables
    g_rule: list[int] = field(default_factory=list)
    g_head: list[int] = field(default_factory=list)
    g_values: list[tuple[int, ...]] = field(default_factory=list)
    g_body: list[list[int]] = field(default_factory=list)
    _closed_once: bool = False

    def __post_init__(self) -> None:
        self._compiled = [self._compile(i, r) for i, r in enumerate(self.rules)]

    def _compile(self, index: int, rule: Rule) -> _CompiledRule:
        variables = rule.variables
        var_index = {v: i for i, v in enumerate(variables)}

        def args_of(lit: Literal) -> list[tuple[bool, int]]:
            return [(True, var_index[t.name]) if t.is_var else (False, self.vocab.node(t.name))
                    for t in lit.args]

        return _CompiledRule(
            index=index, rule=rule, variables=variables,
            head_label=self.vocab.label(rule.head.pred, len(rule.head.args)),
            clause_labels=[self.vocab.label(c.pred, len(c.args)) for c in rule.body],
            clause_args=[args_of(c) for c in rule.body],
            head_args=args_of(rule.head),
            binding=[i for i, c in enumerate(rule.body) if c.binds],
        )

    def add_settable(self, aid: int) -> None:
        """Declare that atom aid can be set (a fact, an external fact, a rule head)."""
        if aid in self.settable:
            return
        self.settable.add(aid)
        self._new.append(aid)
        cols = self.vocab._cols
        label = int(cols[0, aid])
        self._by_label.setdefault(label, []).append(aid)
        for pos, node in enumerate((int(cols[1, aid]), int(cols[2, aid]))):
            if node >= 0:
                self._by_label_arg.setdefault((label, pos, node), []).append(aid)

    def add_settable_many(self, aids: np.ndarray) -> None:
        for a in np.asarray(aids).tolist():
            self.add_settable(a)

    def close(self) -> int:
        """Ground until no new settable atom appears. Returns the number of new groundings."""
        before = len(self.g_rule)
        if not self._new and self._closed_once:  # the usual case at every step: nothing new to ground
            return 0
        self._closed_once = True
        for cr in self._compiled:  # rules without binding clauses have exactly one grounding
            if not cr.binding and (cr.index, ()) not in self._seen:
                self._emit(cr, [])
        while self._new:
            delta = set(self._new)
            self._new = []
            delta_by_label: dict[int, list[int]] = {}
            for aid in sorted(delta):
                delta_by_label.setdefault(int(self.vocab._cols[0, aid]), []).append(aid)
            for cr in self._compiled:
                for ci in cr.binding:
                    atoms = delta_by_label.get(cr.clause_labels[ci])
                    if atoms:
                        self._join(cr, ci, atoms)
        return len(self.g_rule) - before

    def _join(self, cr: _CompiledRule, start: int, start_atoms: list[int]) -> None:
        n_vars = len(cr.variables)
        binding: list[int] = [-1] * n_vars
        rest = [ci for ci in cr.binding if ci != start]

        def match(ci: int, aid: int, trail: list[int]) -> bool:
            """Bind clause ci's variables to atom aid's arguments; False on a clash."""
            nodes = (int(self.vocab._cols[1, aid]), int(self.vocab._cols[2, aid]))
            for pos, (is_var, x) in enumerate(cr.clause_args[ci]):
                node = nodes[pos]
                if not is_var:
                    if x != node:
                        return False
                elif binding[x] < 0:
                    binding[x] = node
                    trail.append(x)
                elif binding[x] != node:
                    return False
            return True

        def candidates(ci: int) -> list[int]:
            label = cr.clause_labels[ci]
            best: list[int] | None = None
            for pos, (is_var, x) in enumerate(cr.clause_args[ci]):
                node = binding[x] if is_var else x
                if node >= 0:
                    lst = self._by_label_arg.get((label, pos, node), [])
                    if best is None or len(lst) < len(best):
                        best = lst
            return self._by_label.get(label, []) if best is None else best

        def bound_count(ci: int) -> int:
            return sum(1 for is_var, x in cr.clause_args[ci] if not is_var or binding[x] >= 0)

        def descend(remaining: list[int]) -> None:
            if not remaining:
                self._emit(cr, binding)
                return
            # the clause with the most bound arguments next: the most selective lookup
            ci = max(remaining, key=bound_count)
            others = [c for c in remaining if c != ci]
            for aid in list(candidates(ci)):
                trail: list[int] = []
                if match(ci, aid, trail):
                    descend(others)
                for x in trail:
                    binding[x] = -1

        for aid in start_atoms:
            trail: list[int] = []
            if match(start, aid, trail):
                descend(rest)
            for x in trail:
                binding[x] = -1

    def _emit(self, cr: _CompiledRule, binding: list[int]) -> None:
        values = tuple(binding)
        key = (cr.index, values)
        if key in self._seen:
            return
        self._seen.add(key)

        def ground(args: list[tuple[bool, int]]) -> tuple[int, ...]:
            return tuple(binding[x] if is_var else x for is_var, x in args)

        head = self.vocab.atom(cr.head_label, ground(cr.head_args))
        body = [self.vocab.atom(lab, ground(args)) for lab, args in zip(cr.clause_labels, cr.clause_args)]
        self.g_rule.append(cr.index)
        self.g_head.append(head)
        self.g_values.append(values)
        self.g_body.append(body)
        self.add_settable(head)

    # ---- integer tables for the kernel and the trace ----

    def ranks(self) -> np.ndarray:
        """Canonical order of groundings: rule index, then the tuple of variable node ids."""
        n = len(self.g_rule)
        if n == 0:
            return np.zeros(0, np.int64)
        width = max((len(v) for v in self.g_values), default=0)
        keys = np.full((n, width + 1), -1, np.int64)
        keys[:, 0] = self.g_rule
        for g, vals in enumerate(self.g_values):
            keys[g, 1:1 + len(vals)] = vals
        order = np.lexsort(keys.T[::-1])
        rank = np.empty(n, np.int64)
        rank[order] = np.arange(n)
        return rank

    def kernel_tables(self, kinds: np.ndarray | None = None,
                      fact_atoms: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """The kernel's tables (engine/kernel.py): `inst` [G,4] (rule, head, rank, kind index from
        `kinds`, a per-rule array), watches grouped in classes (CSR by atom over distinct (bound, sign)
        of the binding clauses that read it, then CSR by class over groundings), the immediate
        groundings by the atom they set, and per-grounding binding clauses (for recounts and the lanes
        kernel's body tests). A grounding's clauses list first those on atoms that rules set or that are
        not program facts (they change), then those on atoms only program facts set (`fact_atoms`, ids):
        a body test that fails on a changing clause stops before reading the fixed ones."""
        n = len(self.g_rule)
        rules = np.asarray(self.g_rule, np.int64)
        inst = np.empty((n, 4), np.int32)
        inst[:, 0] = rules
        inst[:, 1] = self.g_head
        inst[:, 2] = self.ranks()
        inst[:, 3] = kinds[rules] if kinds is not None and n else 0
        b_inst, b_atom, b_neg, b_lo, b_up = [], [], [], [], []
        b_ptr = np.zeros(n + 1, np.int64)
        fixed = np.zeros(self.vocab.n_atoms, np.bool_)
        if fact_atoms is not None and len(fact_atoms):
            fixed[np.asarray(fact_atoms, np.int64)] = True
        if n:
            fixed[np.asarray(self.g_head, np.int64)] = False
        for g in range(n):
            cr = self._compiled[self.g_rule[g]]
            body = self.g_body[g]
            for ci in sorted(cr.binding, key=lambda ci: bool(fixed[body[ci]])):
                lit = cr.rule.body[ci]
                b_inst.append(g)
                b_atom.append(body[ci])
                b_neg.append(lit.negated)
                b_lo.append(lit.lower)
                b_up.append(lit.upper)
            b_ptr[g + 1] = len(b_atom)
        b_atom_a = np.asarray(b_atom, np.int64)
        b_inst_a = np.asarray(b_inst, np.int64)
        b_lo_a, b_up_a = np.asarray(b_lo, np.float64), np.asarray(b_up, np.float64)
        b_neg_a = np.asarray(b_neg, np.bool_)
        b_bnd = np.column_stack([b_lo_a, b_up_a]) if b_atom else np.zeros((0, 2), np.float64)
        n_atoms = self.vocab.n_atoms
        # watch classes: entries sorted by (atom, sign, bound, grounding); a class is one (atom, sign, bound)
        order = np.lexsort((b_inst_a, b_up_a, b_lo_a, b_neg_a, b_atom_a))
        s_atom, s_neg, s_lo, s_up = b_atom_a[order], b_neg_a[order], b_lo_a[order], b_up_a[order]
        new_class = np.ones(len(order), np.bool_)
        if len(order) > 1:
            new_class[1:] = (s_atom[1:] != s_atom[:-1]) | (s_neg[1:] != s_neg[:-1]) \
                | (s_lo[1:] != s_lo[:-1]) | (s_up[1:] != s_up[:-1])
        first = np.flatnonzero(new_class)
        wc_gptr = np.append(first, len(order)).astype(np.int64)
        wc_ptr = np.zeros(n_atoms + 1, np.int64)
        np.add.at(wc_ptr, s_atom[first] + 1, 1)
        np.cumsum(wc_ptr, out=wc_ptr)
        # immediate groundings by the atom they set: when that atom changes they may change it back
        heads = np.asarray(self.g_head, np.int64)
        immediate = np.array([self._compiled[r].rule.immediate for r in self.g_rule], np.bool_)
        imm = np.flatnonzero(immediate) if n else np.zeros(0, np.int64)
        imm = imm[np.lexsort((imm, heads[imm]))]
        ih_ptr = np.zeros(n_atoms + 1, np.int64)
        np.add.at(ih_ptr, heads[imm] + 1, 1)
        np.cumsum(ih_ptr, out=ih_ptr)
        s_code = truth_codes(s_lo, s_up, s_neg)
        return {
            "wc_code": np.ascontiguousarray(s_code[first]),
            "b_code": truth_codes(b_lo_a, b_up_a, b_neg_a),
            "inst": inst,
            "wc_ptr": wc_ptr,
            "wc_bnd": np.ascontiguousarray(np.column_stack([s_lo[first], s_up[first]])
                                           if len(first) else np.zeros((0, 2), np.float64)),
            "wc_neg": np.ascontiguousarray(s_neg[first]),
            "wc_gptr": wc_gptr,
            "wg": b_inst_a[order].astype(np.int32),
            "ih_ptr": ih_ptr,
            "ih_inst": imm.astype(np.int32),
            "b_ptr": b_ptr,
            "b_atom": b_atom_a,
            "b_neg": b_neg_a,
            "b_bnd": np.ascontiguousarray(b_bnd),
        }

    def table(self) -> GroundingTable:
        n = len(self.g_rule)
        body_ptr = np.zeros(n + 1, np.int64)
        var_ptr = np.zeros(n + 1, np.int64)
        body_ptr[1:] = np.cumsum([len(b) for b in self.g_body]) if n else []
        var_ptr[1:] = np.cumsum([len(v) for v in self.g_values]) if n else []
        flat_body = [a for b in self.g_body for a in b]
        flat_vals = [x for v in self.g_values for x in v]
        return GroundingTable(
            rule=np.asarray(self.g_rule, np.int32), body_ptr=body_ptr,
            body_atoms=np.asarray(flat_body, np.int32), var_ptr=var_ptr,
            var_values=np.asarray(flat_vals, np.int32))


def rule_head_bound(rule: Rule) -> tuple[float, float]:
    """The interval a rule's head sets on its atom (a `~` head sets the complement)."""
    return effective_bound(rule.head.lower, rule.head.upper, rule.head.negated)


# the crisp values [0,1], [1,1], [0,0] in the lanes kernel's order (engine/lanes.py: V_U, V_T, V_F)
CRISP_VALUES = ((0.0, 1.0), (1.0, 1.0), (0.0, 0.0))


def truth_codes(lower: np.ndarray, upper: np.ndarray, negated: np.ndarray) -> np.ndarray:
    """Per clause, the crisp values it holds of, as bits (1 << value index): its truth table over
    [0,1], [1,1] and [0,0] (docs/language.md, containment with ε and the complement for `~`)."""
    code = np.zeros(len(lower), np.uint8)
    for v, (a, b) in enumerate(CRISP_VALUES):
        lo = np.where(negated, 1.0 - b, a)
        up = np.where(negated, 1.0 - a, b)
        holds = (lo >= lower - EPS) & (up <= upper + EPS)
        code |= np.where(holds, np.uint8(1 << v), np.uint8(0))
    return code
