"""Grounding: every rule grounding that could ever fire, found once by joins over the atoms that can ever
be set (by facts, external facts or rule heads), and kept as integer tables for the kernel.

An atom that nothing can set stays [0,1] forever, and [0,1] satisfies no *binding* clause, so a grounding
needs one settable atom per binding clause. Groundings are full joins: one value per variable across every
clause. New settable atoms (rule heads, external facts on new atoms) are joined semi-naively: each round
only joins that use at least one new atom are made (a clause before the new atom's clause reads the old
atoms, one after it reads old and new, so no grounding is found twice).

Joins are vectorised: a round joins whole relations (numpy arrays of the settable atoms of a label) by
sorting and searchsorted, and the grounding tables are arrays, so a million groundings cost seconds,
not a Python call each.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from . import head_functions
from .errors import ProgramError
from .head_functions import HeadFunction
from .kernel_tables import KernelTables
from .grounding_limit import limit_in_force
from .program import EPS, Literal, Rule, Term, effective_bound
from .vocabulary import Vocabulary


# Watchers of long groundings (a progress display): called with the groundings found so far after each join.
_watchers: list[Callable[[int], None]] = []


@contextmanager
def watch_grounding(callback: Callable[[int], None]) -> Iterator[None]:
    """Inside: `callback(groundings so far)` after each join of any Grounder, e.g. to show the progress
    of a big build (grounding 20 agents a team takes a minute)."""
    _watchers.append(callback)
    try:
        yield
    finally:
        _watchers.remove(callback)


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
    n_vars: int
    head_label: int
    clause_labels: list[int]
    # per clause and argument position: variable index (>= 0) or -(node id) - 1 for a constant
    clause_args: list[list[int]]
    head_args: list[int]
    binding: list[int]  # indices of enumerating clauses (joins find the groundings through them)
    watched: list[int]  # indices of the clauses a grounding must test: not true of every interval
    on_edges: bool  # `%edge_heads graph` and no {infer_edges}: heads only on the graph's edges
    # per head argument: None, or a head function call (engine/head_functions.py) and its arguments coded
    # as head_args are (its head_args entry is then unused)
    head_calls: list[tuple[Term, HeadFunction, list[int]] | None]


# a planned join: the rule, its start clause, the start atoms, each binding clause's relation, its bound
_Join = tuple[_CompiledRule, int, np.ndarray, dict[int, np.ndarray], int]


def _growable(cap: int, width: int, dtype: type) -> np.ndarray:
    return np.full((cap, width), -1, dtype) if width else np.zeros((cap, 0), dtype)


class Grounder:
    """The groundings of `rules` over the settable atoms of `vocab`, grown by close()."""

    def __init__(self, rules: list[Rule], vocab: Vocabulary, closed: tuple[str, ...] = (),
                 edge_heads: str = "any", edges: np.ndarray | None = None, max_groundings: int | None = None
                 ) -> None:
        """`closed`: the %closed predicates; `edges`: node-id pairs [E, 2] of the graph's edges, where the
        edge heads of rules without {infer_edges} land under `%edge_heads graph`. `max_groundings`: close()
        refuses (ProgramError at the rule) to ground past it; None: engine/grounding_limit.py's limit."""
        self.max_groundings, self.limit_source = limit_in_force(max_groundings)
        self.estimated = 0  # the sum of the bounds of the joins made: >= n_groundings
        self.rules = rules
        self.vocab = vocab
        self.closed = frozenset(closed)
        self.edge_heads = edge_heads
        pairs = np.zeros((0, 2), np.int64) if edges is None else np.asarray(edges, np.int64).reshape(-1, 2)
        self._edge_keys = sorted_unique((pairs[:, 0] << 24) | pairs[:, 1])
        self._compiled = [self._compile(i, r) for i, r in enumerate(rules)]
        self.max_vars = max((cr.n_vars for cr in self._compiled), default=0)
        self.max_body = max((len(r.body) for r in rules), default=0)
        self._rule_nvars = np.array([cr.n_vars for cr in self._compiled], np.int64)
        self._rule_nbody = np.array([len(r.body) for r in rules], np.int64)
        self._n = 0
        self._rule = np.zeros(1024, np.int32)
        # atom and node ids fit int32 (vocabulary.py): a million groundings' tables stay small
        self._head = np.zeros(1024, np.int32)
        self._vals = _growable(1024, self.max_vars, np.int32)
        self._body = _growable(1024, self.max_body, np.int32)
        self._settable = np.zeros(1024, np.bool_)  # by atom id: settable (joined, or pending in _pending)
        self.n_settable = 0
        self._pending: list[np.ndarray] = []
        self._by_label: dict[int, list[np.ndarray]] = {}  # joined settable atoms per label, in chunks
        # (label, clause shape) -> (relation size, figure) of _clause_figure: a bound's figures, kept
        self._figures: dict[tuple[int, tuple], tuple[int, int]] = {}
        self._closed_once = False

    def _compile(self, index: int, rule: Rule) -> _CompiledRule:
        var_index = {v: i for i, v in enumerate(rule.variables)}

        def args_of(lit: Literal) -> list[int]:
            return [var_index[t.name] if t.is_var else -self.vocab.node(t.name) - 1 if t.function is None else 0
                    for t in lit.args]

        def call_of(t: Term) -> tuple[Term, HeadFunction, list[int]] | None:
            if t.function is None:
                return None
            return t, head_functions.bind(t), args_of(Literal("", t.call_args))

        return _CompiledRule(
            index=index, rule=rule, n_vars=len(var_index),
            head_label=self.vocab.label(rule.head.pred, len(rule.head.args)),
            clause_labels=[self.vocab.label(c.pred, len(c.args)) for c in rule.body],
            clause_args=[args_of(c) for c in rule.body],
            head_args=args_of(rule.head),
            # quantified clauses are neither enumerated nor watched: the kernel counts them per head group
            binding=rule.binding_clauses(self.closed),
            watched=rule.watched_clauses(),
            on_edges=self.edge_heads == "graph" and len(rule.head.args) == 2 and not rule.infer_edges,
            head_calls=[call_of(t) for t in rule.head.args],
        )

    # ---- sizes and state ----

    @property
    def n_groundings(self) -> int:
        return self._n

    @property
    def g_rule(self) -> np.ndarray:
        return self._rule[:self._n]

    @property
    def g_head(self) -> np.ndarray:
        return self._head[:self._n]

    @property
    def has_pending(self) -> bool:
        return bool(self._pending) or not self._closed_once

    def settable_mask(self, n_atoms: int) -> np.ndarray:
        """bool[n_atoms]: which atoms can be set (facts, external facts, rule heads)."""
        out = np.zeros(n_atoms, np.bool_)
        k = min(n_atoms, len(self._settable))
        out[:k] = self._settable[:k]
        return out

    def _fit_atoms(self) -> None:
        n = self.vocab.n_atoms
        if n > len(self._settable):
            grown = np.zeros(max(n, 2 * len(self._settable)), np.bool_)
            grown[:len(self._settable)] = self._settable
            self._settable = grown

    # ---- settable atoms ----

    def add_settable_many(self, aids: np.ndarray) -> None:
        aids = np.asarray(aids, np.int64)
        if not len(aids):
            return
        self._fit_atoms()
        new = aids[~self._settable[aids]]
        if len(new):
            new = sorted_unique(new)
            self._settable[new] = True
            self.n_settable += len(new)
            self._pending.append(new)

    # ---- grounding ----

    def close(self) -> int:
        """Ground until no new settable atom appears. Returns the number of new groundings."""
        before = self._n
        if not self._pending and self._closed_once:  # the usual case at every step: nothing new to ground
            return 0
        if not self._closed_once:
            self._closed_once = True
            for cr in self._compiled:  # rules without binding clauses have exactly one grounding
                if not cr.binding:
                    self._emit(cr, np.zeros((1, cr.n_vars), np.int64))
                    self.estimated += 1
        while self._pending:
            delta = np.concatenate(self._pending)  # distinct: add_settable_many never repeats an atom
            self._pending = []
            self._fit_atoms()
            delta_label = self.vocab.atom_label[delta]
            delta_by_label = {int(lab): delta[delta_label == lab] for lab in sorted_unique(delta_label)}
            joins = self._round(delta_by_label)
            self._check_limit(joins)
            for cr, ci, start, rels, _ in joins:
                self._join(cr, ci, start, rels)
                for watch in _watchers:
                    watch(self._n)
            for lab, atoms in delta_by_label.items():
                self._by_label.setdefault(lab, []).append(atoms)
        return self._n - before

    def _round(self, delta_by_label: dict[int, np.ndarray]) -> list[_Join]:
        """The joins of one semi-naive round, each with its bound (_join_bound). Relations are fixed for
        the round (heads it emits are joined in the next one), so all are planned before any is made."""
        labels = {lab for cr in self._compiled for lab in cr.clause_labels}
        # this round's relations: old (joined before) and all (old and delta), per label
        old = {lab: self._relation(lab) for lab in labels}
        every = {lab: np.concatenate([old[lab], d]) for lab, d in delta_by_label.items() if lab in labels}
        joins = []
        memo: dict[tuple, np.ndarray] = {}
        for cr in self._compiled:
            for pos, ci in enumerate(cr.binding):
                start = delta_by_label.get(cr.clause_labels[ci])
                if start is None:
                    continue
                rels = {cj: old[cr.clause_labels[cj]] if pos2 < pos else every.get(cr.clause_labels[cj],
                                                                                      old[cr.clause_labels[cj]])
                        for pos2, cj in enumerate(cr.binding)}
                joins.append((cr, ci, start, rels, self._join_bound(cr, ci, start, rels, memo)))
        return joins

    def _check_limit(self, joins: list[_Join]) -> None:
        """Refuse a round whose joins could take the groundings past the limit, before any of them is
        made, naming the rule that would have the most (those it has, and its bounds in this round)."""
        bound = sum(j[4] for j in joins)
        self.estimated += bound
        if self._n + bound <= self.max_groundings:
            return
        per_rule = np.bincount(self.g_rule, minlength=len(self.rules)).tolist()
        for cr, _, _, _, b in joins:
            per_rule[cr.index] += b
        worst = max(range(len(per_rule)), key=per_rule.__getitem__)
        rule, total = self.rules[worst], self._n + bound
        program = "" if per_rule[worst] == total else f"; the program's up to {total:,}"
        raise self._refused(rule, f"rule '{rule.name}' would make up to {per_rule[worst]:,} groundings "
                                  f"(estimated before grounding{program})")

    def _check_rows(self, cr: _CompiledRule, rows: int) -> None:
        """Refuse a join whose next stage would hold more rows than the limit, before allocating them
        (the bound is of a join's result; _join's clause order may pass through more rows than that)."""
        if rows > self.max_groundings:
            raise self._refused(cr.rule, f"grounding rule '{cr.rule.name}' takes {rows:,} rows at once (its "
                                         "clauses joined in the grounder's order)")

    def _refused(self, rule: Rule, what: str) -> ProgramError:
        return ProgramError.at(rule.loc, (
            f"{what}, more than the limit of {self.max_groundings:,} groundings ({self.limit_source}); raise "
            "it with --max-groundings N (Engine(max_groundings=N)) if the machine has the memory"))

    def _relation(self, label: int) -> np.ndarray:
        chunks = self._by_label.get(label)
        if not chunks:
            return np.zeros(0, np.int64)
        if len(chunks) > 1:
            self._by_label[label] = chunks = [np.concatenate(chunks)]
        return chunks[0]

    def _filtered(self, args: list[int], atoms: np.ndarray, bound: np.ndarray
                  ) -> tuple[list[np.ndarray], np.ndarray, dict[int, int]]:
        """A clause's atoms that match its constants and a variable repeated inside it (not yet bound):
        their argument columns, the atoms, and the clause's new variables (variable -> position)."""
        cols = self.vocab._cols
        a = [cols[1, atoms].astype(np.int64), cols[2, atoms].astype(np.int64)]
        keep = np.ones(len(atoms), np.bool_)
        new_vars: dict[int, int] = {}
        for p, x in enumerate(args):
            if x < 0:
                keep &= a[p] == -x - 1
            elif not bound[x]:
                if x in new_vars:
                    keep &= a[p] == a[new_vars[x]]
                else:
                    new_vars[x] = p
        if not keep.all():
            a = [a[0][keep], a[1][keep]]
            atoms = atoms[keep]
        return a, atoms, new_vars

    @staticmethod
    def _next_clause(cr: _CompiledRule, remaining: list[int], bound: np.ndarray) -> int:
        """The next clause to join: the one with the most bound arguments (the most selective lookup)."""
        ci = max(remaining, key=lambda c: sum(1 for x in cr.clause_args[c] if x < 0 or bound[x]))
        remaining.remove(ci)
        return ci

    def _packed_key(self, columns: list[np.ndarray]) -> np.ndarray:
        """The node ids of some bound variables (a column each, one row per row) packed into one int64."""
        n_nodes = np.int64(max(len(self.vocab.nodes), 1))
        key = np.zeros(len(columns[0]), np.int64)
        for c in columns:
            key = key * n_nodes + c
        return key

    def _join_bound(self, cr: _CompiledRule, start: int, start_atoms: np.ndarray, rels: dict[int, np.ndarray],
                    memo: dict[tuple, np.ndarray]) -> int:
        """An upper bound on the groundings _join(cr, start, ...) finds, without enumerating them. The
        clauses are taken in the order that multiplies the rows least (not _join's order: the bound is
        of the result, which no order changes): the start clause's matching atoms; exactly the rows of
        their join with the next clause (a count per key); then per further clause the most of its atoms
        that share one value of the variables bound so far (all of them if it shares none). `memo`:
        sorted keys of clauses' relations, shared by the joins of one round (most of them read the same
        relations the same way)."""
        bound = np.zeros(cr.n_vars, np.bool_)
        remaining = [ci for ci in cr.binding if ci != start]
        a, _, new_vars = self._filtered(cr.clause_args[start], start_atoms, bound)
        first = np.full((len(a[0]), cr.n_vars), -1, np.int64)  # the start rows' values, for the exact stage
        for x, p in new_vars.items():
            first[:, x] = a[p]
            bound[x] = True
        rows = len(a[0])
        while remaining and rows:
            factor, ci = min((self._clause_figure(cr.clause_labels[c], cr.clause_args[c], rels[c], bound, False,
                                                  memo), c) for c in remaining)
            remaining.remove(ci)
            args = cr.clause_args[ci]
            keyed = any(x >= 0 and bound[x] for x in args)
            if first is not None and keyed:  # the second clause: how many of its atoms each start row meets
                sk = self._clause_figure(cr.clause_labels[ci], args, rels[ci], bound, True, memo)
                lkey = self._packed_key([first[:, x] for x in args if x >= 0 and bound[x]])
                rows = int((np.searchsorted(sk, lkey, "right") - np.searchsorted(sk, lkey, "left")).sum())
            else:
                rows *= int(factor)
            first = None
            for x in args:
                if x >= 0:
                    bound[x] = True
        return rows

    def _clause_figure(self, label: int, args: list[int], rel: np.ndarray, bound: np.ndarray, exact: bool,
                       memo: dict[tuple, np.ndarray]) -> int | np.ndarray:
        """How a clause joined next multiplies the rows: its matching atoms if it shares no bound
        variable, else the most atoms sharing one key; with `exact`, the sorted keys instead (to count
        the atoms each row meets; kept in `memo`, for one round). A label's relation only grows (its
        first n atoms are always the same), so its figures are kept by length from round to round."""
        shape = tuple(("=", -x - 1) if x < 0 else "key" if bound[x] else ("var", args.index(x)) for x in args)
        has_key = "key" in shape
        if exact and has_key:
            entry = (label, len(rel), shape)
            if entry not in memo:
                a, _, _ = self._filtered(args, rel, bound)
                memo[entry] = np.sort(self._packed_key([a[p] for p, k in enumerate(shape) if k == "key"]))
            return memo[entry]
        size, figure = self._figures.get((label, shape), (-1, 0))
        if size != len(rel):
            a, _, _ = self._filtered(args, rel, bound)
            figure = _most_per_key(self._packed_key([a[p] for p, k in enumerate(shape) if k == "key"])) \
                if has_key else len(a[0])
            self._figures[(label, shape)] = (len(rel), figure)
        return figure

    def _join(self, cr: _CompiledRule, start: int, start_atoms: np.ndarray, rels: dict[int, np.ndarray]) -> None:
        """Every binding of cr's variables with clause `start` on start_atoms and the other binding
        clauses on their relations; emits the groundings."""
        bound = np.zeros(cr.n_vars, np.bool_)
        rows = np.full((0, cr.n_vars), -1, np.int64)
        first = True
        found: dict[int, np.ndarray] = {}  # binding clause -> its atom per row
        remaining = [ci for ci in cr.binding if ci != start]
        ci, atoms = start, start_atoms
        while True:
            args = cr.clause_args[ci]
            a, atoms, new_vars = self._filtered(args, atoms, bound)
            key_vars = [(p, x) for p, x in enumerate(args) if x >= 0 and bound[x]]
            if first:
                rows = np.full((len(a[0]), cr.n_vars), -1, np.int64)
                first = False
                left = np.arange(len(a[0]))
                right_idx = left
            elif not key_vars:  # a clause sharing no variable: every pair
                self._check_rows(cr, len(rows) * len(a[0]))
                left = np.repeat(np.arange(len(rows)), len(a[0]))
                right_idx = np.tile(np.arange(len(a[0])), len(rows))
            else:
                rkey = self._packed_key([a[p] for p, _ in key_vars])
                lkey = self._packed_key([rows[:, x] for _, x in key_vars])
                order = np.argsort(rkey, kind="stable")
                sk = rkey[order]
                lo = np.searchsorted(sk, lkey, "left")
                hi = np.searchsorted(sk, lkey, "right")
                counts = hi - lo
                self._check_rows(cr, int(counts.sum()))
                left = np.repeat(np.arange(len(rows)), counts)
                offs = np.arange(len(left)) - np.repeat(np.cumsum(counts) - counts, counts)
                right_idx = order[np.repeat(lo, counts) + offs]
            rows = rows[left]
            found = {c: ids[left] for c, ids in found.items()}
            found[ci] = atoms[right_idx]  # the clause's atom in each row: no lookup needed later
            for x, p in new_vars.items():
                rows[:, x] = a[p][right_idx]
                bound[x] = True
            if not remaining or not len(rows):
                break
            ci = self._next_clause(cr, remaining, bound)
            atoms = rels[ci]
        if len(rows):
            self._emit(cr, rows, found)

    def _on_edges(self, cr: _CompiledRule, rows: np.ndarray, found: dict[int, np.ndarray] | None
                  ) -> tuple[np.ndarray, dict[int, np.ndarray] | None]:
        """The rows whose head (source, target) is an edge of the graph."""
        src, dst = self._head_columns(cr, rows)
        keys = (src << 24) | dst
        pos = np.minimum(np.searchsorted(self._edge_keys, keys), max(len(self._edge_keys) - 1, 0))
        keep = self._edge_keys[pos] == keys if len(self._edge_keys) else np.zeros(len(rows), np.bool_)
        return rows[keep], None if found is None else {c: a[keep] for c, a in found.items()}

    @staticmethod
    def argument_columns(args: list[int], rows: np.ndarray) -> list[np.ndarray]:
        """Node ids per row of each argument (a variable's column or a constant)."""
        return [np.full(len(rows), -x - 1, np.int64) if x < 0 else rows[:, x].astype(np.int64) for x in args]

    def _head_columns(self, cr: _CompiledRule, rows: np.ndarray) -> list[np.ndarray]:
        """The head's node ids per row, a head function call's computed (once per distinct arguments)."""
        cols = self.argument_columns(cr.head_args, rows)
        for k, hc in enumerate(cr.head_calls):
            if hc is not None:
                cols[k] = self._called(cr, *hc, rows)
        return cols

    def _called(self, cr: _CompiledRule, term: Term, fn: HeadFunction, args: list[int], rows: np.ndarray
                ) -> np.ndarray:
        arg_cols = (np.stack(self.argument_columns(args, rows), axis=1) if len(rows)
                    else np.zeros((0, len(args)), np.int64))
        distinct, inverse = np.unique(arg_cols, axis=0, return_inverse=True)
        nodes = self.vocab.nodes
        out = np.empty(len(distinct), np.int64)
        for i, ids in enumerate(distinct):
            names = tuple(nodes[x] for x in ids)
            try:
                name = head_functions.call(fn, term, names, cr.rule.name)
            except head_functions.HeadFunctionError as e:
                raise ProgramError.at(cr.rule.loc, str(e)) from None
            nid = self.vocab.node_ids.get(name)
            if nid is None:
                raise ProgramError.at(cr.rule.loc, f"head function '{term.function}' (rule {cr.rule.name}) "
                                      f"returned {name!r} for {', '.join(names)}, which is not a node of the "
                                      "program or its graph")
            out[i] = nid
        return out[inverse.reshape(-1)]

    def _ground_atoms(self, label: int, args: list[int], rows: np.ndarray,
                      cols: list[np.ndarray] | None = None) -> np.ndarray:
        cols = cols if cols is not None else self.argument_columns(args, rows)
        a1 = cols[1] if len(cols) > 1 else np.full(len(rows), -1, np.int64)
        return self.vocab.atoms(np.full(len(rows), label, np.int64), cols[0], a1)

    def _emit(self, cr: _CompiledRule, rows: np.ndarray, found: dict[int, np.ndarray] | None = None) -> None:
        """Append groundings (variable values per row); `found`: atoms of binding clauses known already."""
        if cr.on_edges:
            rows, found = self._on_edges(cr, rows, found)
        m = len(rows)
        heads = self._ground_atoms(cr.head_label, cr.head_args, rows, self._head_columns(cr, rows))
        found = found or {}
        body = [found[ci] if ci in found else self._ground_atoms(lab, args, rows)
                for ci, (lab, args) in enumerate(zip(cr.clause_labels, cr.clause_args))]
        n = self._n
        self._room_for(n + m)
        self._rule[n:n + m] = cr.index
        self._head[n:n + m] = heads
        self._vals[n:n + m, :cr.n_vars] = rows
        for ci, atoms in enumerate(body):
            self._body[n:n + m, ci] = atoms
        self._n = n + m
        self.add_settable_many(heads)

    def _room_for(self, groundings: int) -> None:
        if groundings > len(self._rule):
            cap = max(groundings, 2 * len(self._rule))
            self._rule = np.concatenate([self._rule, np.zeros(cap - len(self._rule), np.int32)])
            self._head = np.concatenate([self._head, np.zeros(cap - len(self._head), np.int32)])
            self._vals = np.concatenate([self._vals, _growable(cap - len(self._vals), self.max_vars, np.int32)])
            self._body = np.concatenate([self._body, _growable(cap - len(self._body), self.max_body, np.int32)])

    # ---- a close's result, as the grounding cache keeps it (grounding_cache.py) ----

    @property
    def compiled_rules(self) -> list[_CompiledRule]:
        return self._compiled

    def state_parts(self) -> Iterator[bytes]:
        """Everything of the grounder's state that decides what close() finds, besides its rules and the
        vocabulary (which the grounding cache hashes itself)."""
        n = self._n
        yield repr((self._closed_once, self.n_settable, sorted(self.closed), self.edge_heads,
                    self.max_groundings)).encode()
        yield self._edge_keys.tobytes()
        for a in (self._rule[:n], self._head[:n], self._vals[:n], self._body[:n]):
            yield a.tobytes()
        yield self.settable_mask(self.vocab.n_atoms).tobytes()
        yield np.concatenate([np.zeros(0, np.int64), *self._pending]).tobytes()
        for label in sorted(self._by_label):
            yield label.to_bytes(4, "little") + self._relation(label).tobytes()

    def relations(self) -> tuple[np.ndarray, np.ndarray]:
        """Every label's joined settable atoms, in the order joined: (ptr int64[labels + 1], atoms int64)."""
        rels = [self._relation(label) for label in range(len(self.vocab.labels))]
        ptr = np.zeros(len(rels) + 1, np.int64)
        np.cumsum([len(r) for r in rels], out=ptr[1:])
        return ptr, np.concatenate([np.zeros(0, np.int64), *rels])

    def grown_since(self, groundings_before: int) -> dict[str, np.ndarray]:
        """What close() added after `groundings_before` groundings: the new groundings' rows, the settable
        atoms and the relations (whole)."""
        n = self._n
        ptr, atoms = self.relations()
        return {"rule": self._rule[groundings_before:n], "head": self._head[groundings_before:n],
                "vals": self._vals[groundings_before:n], "body": self._body[groundings_before:n],
                "settable": self.settable_mask(self.vocab.n_atoms).view(np.uint8),
                "relation_ptr": ptr, "relation_atoms": atoms}

    def take_grown(self, grown: dict[str, np.ndarray], estimated_added: int) -> None:
        """The state close() would reach, from grown_since()'s arrays of a close from this very state (the
        grounding cache's, checked by it; the vocabulary already holds the atoms that close interned)."""
        n, m = self._n, len(grown["rule"])
        self._room_for(n + m)
        for mine, name in ((self._rule, "rule"), (self._head, "head"), (self._vals, "vals"), (self._body, "body")):
            mine[n:n + m] = grown[name]
        self._n = n + m
        self._settable = grown["settable"].astype(np.bool_)
        self.n_settable = int(self._settable.sum())
        ptr, atoms = grown["relation_ptr"], grown["relation_atoms"]
        self._by_label = {label: [atoms[ptr[label]:ptr[label + 1]]] for label in range(len(ptr) - 1)
                          if ptr[label + 1] > ptr[label]}
        self._pending = []
        self._closed_once = True
        self.estimated += estimated_added
        for watch in _watchers:
            watch(self._n)

    # ---- integer tables for the kernel and the trace ----

    def ranks(self) -> np.ndarray:
        """Canonical order of groundings: rule index, then the tuple of variable node ids."""
        n = self._n
        if n == 0:
            return np.zeros(0, np.int64)
        node_bits = (len(self.vocab.nodes) + 1).bit_length()
        if len(self.rules).bit_length() + self.max_vars * node_bits <= 62:  # one packed key: one argsort
            key = self.g_rule.astype(np.int64)
            for v in range(self.max_vars):
                key = (key << node_bits) | (self._vals[:n, v].astype(np.int64) + 1)
            order = np.argsort(key, kind="stable")
        else:
            keys = np.empty((n, self.max_vars + 1), np.int64)
            keys[:, 0] = self.g_rule
            keys[:, 1:] = self._vals[:n]
            order = np.lexsort(keys.T[::-1])
        rank = np.empty(n, np.int64)
        rank[order] = np.arange(n)
        return rank

    def kernel_tables(self, kinds: np.ndarray | None = None,
                      fact_atoms: np.ndarray | None = None) -> KernelTables:
        """The kernel's tables (engine/kernel_tables.py): `inst` [G,4] (rule, head, rank, kind index from
        `kinds`, a per-rule array), watches grouped in classes (CSR by atom over distinct (bound, sign)
        of the binding clauses that read it, then CSR by class over groundings), the immediate
        groundings by the atom they set, and per-grounding binding clauses (for recounts and the lanes
        kernel's body tests). A grounding's clauses list first those on atoms that rules set or that are
        not program facts (they change), then those on atoms only program facts set (`fact_atoms`, ids):
        a body test that fails on a changing clause stops before reading the fixed ones."""
        n = self._n
        rules = self.g_rule.astype(np.int64)
        inst = np.empty((n, 4), np.int32)
        inst[:, 0] = rules
        inst[:, 1] = self.g_head
        inst[:, 2] = self.ranks()
        inst[:, 3] = kinds[rules] if kinds is not None and n else 0
        fixed = np.zeros(self.vocab.n_atoms, np.bool_)
        if fact_atoms is not None and len(fact_atoms):
            fixed[np.asarray(fact_atoms, np.int64)] = True
        if n:
            fixed[self.g_head] = False
        n_bind = np.array([len(cr.watched) for cr in self._compiled], np.int64)
        b_ptr = np.zeros(n + 1, np.int64)
        np.cumsum(n_bind[rules], out=b_ptr[1:])
        total = int(b_ptr[-1])
        b_atom_a = np.empty(total, np.int64)
        b_inst_a = np.repeat(np.arange(n, dtype=np.int64), n_bind[rules])
        # a clause's test (sign, lower, upper, closed) as a small id, numbered in that sort order
        tests = sorted({self._test(lit) for cr in self._compiled for lit in (cr.rule.body[ci] for ci in cr.watched)})
        test_id = {t: i for i, t in enumerate(tests)}
        t_neg = np.array([t[0] for t in tests], np.bool_)
        t_lo = np.array([t[1] for t in tests], np.float64)
        t_up = np.array([t[2] for t in tests], np.float64)
        t_closed = np.array([t[3] for t in tests], np.bool_)
        # the kernel's clause flags: 1 the complement (`~`), 2 a closed predicate (docs/language.md)
        t_flags = (t_neg.astype(np.uint8) | (t_closed.astype(np.uint8) << np.uint8(1))).astype(np.uint8)
        b_test = np.empty(total, np.int64)
        for cr in self._compiled:  # one rule's groundings at once: its watched clauses, changing ones first
            if not cr.watched:
                continue
            gs = np.flatnonzero(rules == cr.index)
            if not len(gs):
                continue
            atoms = self._body[gs][:, cr.watched]
            order = np.argsort(fixed[atoms], axis=1, kind="stable")
            pos = b_ptr[gs][:, None] + np.arange(len(cr.watched))
            b_atom_a[pos] = np.take_along_axis(atoms, order, axis=1)
            lits = [cr.rule.body[ci] for ci in cr.watched]
            b_test[pos] = np.array([test_id[self._test(lit)] for lit in lits])[order]
        b_flags_a, b_lo_a, b_up_a = t_flags[b_test], t_lo[b_test], t_up[b_test]
        b_bnd = np.column_stack([b_lo_a, b_up_a]) if total else np.zeros((0, 2), np.float64)
        n_atoms = self.vocab.n_atoms
        # watch classes: entries sorted by (atom, test, grounding); a class is one (atom, test)
        t_bits, g_bits = max(len(tests), 1).bit_length(), max(n, 1).bit_length()
        if max(n_atoms, 1).bit_length() + t_bits + g_bits <= 63:  # one packed key: one argsort
            order = np.argsort((((b_atom_a << t_bits) | b_test) << g_bits) | b_inst_a, kind="stable")
        else:
            order = np.lexsort((b_inst_a, b_test, b_atom_a))
        s_atom, s_test = b_atom_a[order], b_test[order]
        new_class = np.ones(len(order), np.bool_)
        if len(order) > 1:
            new_class[1:] = (s_atom[1:] != s_atom[:-1]) | (s_test[1:] != s_test[:-1])
        first = np.flatnonzero(new_class)
        wc_gptr = np.append(first, len(order)).astype(np.int64)
        wc_ptr = np.zeros(n_atoms + 1, np.int64)
        np.add.at(wc_ptr, s_atom[first] + 1, 1)
        np.cumsum(wc_ptr, out=wc_ptr)
        # immediate groundings by the atom they set: when that atom changes they may change it back
        heads = self.g_head
        immediate = np.array([cr.rule.immediate for cr in self._compiled], np.bool_)[rules]
        imm = np.flatnonzero(immediate) if n else np.zeros(0, np.int64)
        imm = imm[np.lexsort((imm, heads[imm]))]
        ih_ptr = np.zeros(n_atoms + 1, np.int64)
        np.add.at(ih_ptr, heads[imm] + 1, 1)
        np.cumsum(ih_ptr, out=ih_ptr)
        t_code = truth_codes(t_lo, t_up, t_neg, t_closed)
        w_test = s_test[first]
        # offsets and atom ids as int32 (tables of over 2^31 entries would not fit in memory here anyway):
        # per atom and per binding clause, int64 cost a million-edge graph 25 MB more
        return KernelTables(
            inst=inst,
            wc_ptr=wc_ptr.astype(np.int32),
            wc_bnd=np.ascontiguousarray(np.column_stack([t_lo[w_test], t_up[w_test]])
                                        if len(first) else np.zeros((0, 2), np.float64)),
            wc_flags=t_flags[w_test],
            wc_code=t_code[w_test],
            wc_gptr=wc_gptr.astype(np.int32),
            wg=b_inst_a[order].astype(np.int32),
            ih_ptr=ih_ptr.astype(np.int32),
            ih_inst=imm.astype(np.int32),
            b_ptr=b_ptr.astype(np.int32),
            b_atom=b_atom_a.astype(np.int32),
            b_flags=b_flags_a,
            b_bnd=np.ascontiguousarray(b_bnd),
            b_code=t_code[b_test],
        )

    def body_atoms(self, groundings: np.ndarray) -> np.ndarray:
        """int64[len(groundings), max_body]: every clause's atom per grounding (-1 past a rule's body)."""
        return self._body[np.asarray(groundings, np.int64)]

    def _test(self, lit: Literal) -> tuple[bool, float, float, bool]:
        """A watched clause's test: sign, bound, and whether its predicate is closed."""
        return (lit.negated, lit.lower, lit.upper, lit.pred in self.closed)

    def table(self) -> GroundingTable:
        n = self._n
        rules = self.g_rule
        n_body, n_vars = self._rule_nbody[rules], self._rule_nvars[rules]
        body_ptr = np.zeros(n + 1, np.int64)
        var_ptr = np.zeros(n + 1, np.int64)
        np.cumsum(n_body, out=body_ptr[1:])
        np.cumsum(n_vars, out=var_ptr[1:])
        body_mask = np.arange(self.max_body) < n_body[:, None]
        var_mask = np.arange(self.max_vars) < n_vars[:, None]
        return GroundingTable(
            rule=rules.astype(np.int32), body_ptr=body_ptr, body_atoms=self._body[:n][body_mask].astype(np.int32),
            var_ptr=var_ptr, var_values=self._vals[:n][var_mask].astype(np.int32))


def _most_per_key(keys: np.ndarray) -> int:
    """How often the most frequent value of `keys` occurs (0 if empty)."""
    if not len(keys):
        return 0
    s = np.sort(keys)
    starts = np.flatnonzero(np.concatenate([[True], s[1:] != s[:-1], [True]]))
    return int(np.diff(starts).max())


def sorted_unique(x: np.ndarray) -> np.ndarray:
    """np.unique by sorting (numpy's hash-based unique is slower on a million ids:
    docs/benchmarks.md, "Figures behind the code")."""
    s = np.sort(x)
    return s[np.concatenate([[True], s[1:] != s[:-1]])] if len(s) else s


def rule_head_bound(rule: Rule) -> tuple[float, float]:
    """The interval a rule's head sets on its atom (a `~` head sets the complement)."""
    return effective_bound(rule.head.lower, rule.head.upper, rule.head.negated)


# the crisp values [0,1], [1,1], [0,0] in the lanes kernel's order (engine/lanes.py: V_U, V_T, V_F)
CRISP_VALUES = ((0.0, 1.0), (1.0, 1.0), (0.0, 0.0))


def truth_codes(lower: np.ndarray, upper: np.ndarray, negated: np.ndarray,
                closed: np.ndarray | None = None) -> np.ndarray:
    """Per clause, the crisp values it holds of, as bits (1 << value index): its truth table over
    [0,1], [1,1] and [0,0] (docs/language.md, containment with ε and the complement for `~`). On a
    closed predicate [0,1] reads as [0,0], so its bit is the [0,0] bit."""
    code = np.zeros(len(lower), np.uint8)
    for v, (a, b) in enumerate(CRISP_VALUES):
        lo = np.where(negated, 1.0 - b, a)
        up = np.where(negated, 1.0 - a, b)
        holds = (lo >= lower - EPS) & (up <= upper + EPS)
        code |= np.where(holds, np.uint8(1 << v), np.uint8(0))
    if closed is not None:
        unset_bit = (code >> np.uint8(2)) & np.uint8(1)  # the [0,0] bit (CRISP_VALUES index 2)
        code = np.where(closed, (code & np.uint8(6)) | unset_bit, code).astype(np.uint8)
    return code
