"""The engine's trace rows in PyReason's rule-trace CSV layout (its Output class with atom_trace on):
rule_trace_nodes_<timestamp>.csv and rule_trace_edges_<timestamp>.csv with the columns

    Time, Fixed-Point-Operation, Node | Edge, Label, Old Bound, New Bound, Occurred Due To,
    Consistent, Triggered By, Inconsistency Message, Clause-1, Clause-2, ...

Bounds print as Python floats (`[1.0,1.0]`), an edge as a Python tuple (`('Justin', 'Mary')`), a clause
as the list of its atoms' nodes or edges in the grounding that caused the row. As in PyReason (default
settings) the graph's own facts and the resets of non-persistent timesteps are not rows.
Fixed-Point-Operation counts ordinary passes over the whole run: a row of pass p at step t has the number
of passes of steps 0..t-1 plus p (PyReason's fp_cnt)."""
from __future__ import annotations

import csv
import os
import time
from typing import Any

import numpy as np

from tracelab.engine import CAUSE_EXTERNAL, CAUSE_FACT, CAUSE_POLICY, CAUSE_RESET, CAUSE_RULE

from tracelab.engine.program import effective_bound

from .fact_sequence import StepFact, applied_one_by_one, conflict_message, on_frozen_atom
from .names import NameMap
from .translate import DOMAIN

NODE_HEADER = ["Time", "Fixed-Point-Operation", "Node", "Label", "Old Bound", "New Bound", "Occurred Due To",
               "Consistent", "Triggered By", "Inconsistency Message"]
EDGE_HEADER = ["Edge" if h == "Node" else h for h in NODE_HEADER]
GRAPH_ATTRIBUTE_FACT = "graph-attribute-fact"  # PyReason's `Occurred Due To` of a graph attribute's row


def _bound(lo: float, up: float) -> str:
    return f"[{float(lo)!r},{float(up)!r}]"


class PyReasonTrace:
    """Collects the rows of each step (`add`) and writes the two CSV files (`write`). A row holds its
    component as PyReason's DataFrame does (a node id, an edge as a tuple) and each clause as a list of
    components (`get_rule_trace`); the CSV prints them as Python does. `node_bounds` / `edge_bounds` hold
    each row's new bound as numbers (`filter_and_sort_nodes`)."""

    def __init__(self, engine: Any, names: NameMap | None = None, graph_facts: int = 0,
                 ipl_rules: dict[str, str] | None = None, *, skip_graph_facts: bool = True,
                 ipl_twin_rules: dict[str, str] | None = None, ipl_facts: dict[str, tuple[str, str]] | None = None,
                 ipl_partners: dict[str, str] | None = None) -> None:
        self.engine = engine
        self.ipl_rules = ipl_rules or {}  # the inconsistent predicate list's rules -> the predicate they copy
        self.ipl_twin_rules = ipl_twin_rules or {}  # translate.ipl_twins' rules -> their rule's PyReason name
        self.ipl_facts = ipl_facts or {}  # translate.ipl_facts' facts -> (the predicate copied, its fact's name)
        self.ipl_partners = ipl_partners or {}  # a PyReason predicate -> its IPL partner
        self._rule_numbers: dict[str, int] | None = None  # a rule's PyReason name -> its engine index
        self.names = names or NameMap()
        self.graph_facts = graph_facts  # the engine's facts 0..graph_facts-1 are the graph's attributes
        self.skip_graph_facts = skip_graph_facts  # PyReason's save_graph_attributes_to_trace=False
        self.node_rows: list[list[object]] = []
        self.edge_rows: list[list[object]] = []
        self.clauses = {"node": 0, "edge": 0}
        self.external_names: dict[int, str] = {}  # external facts' names by their id (pr.reason(again=True))
        self.node_bounds: list[tuple[float, float]] = []
        self._facts: dict[int, list[tuple[int, int, StepFact]]] | None = None  # _facts_by_atom
        self.frozen: set[int] = set()  # atoms a conflict of facts froze (static from then on)
        self.static_before: np.ndarray | None = None  # the engine's static flags after the last step added
        self.edge_bounds: list[tuple[float, float]] = []

    def carry(self, earlier: PyReasonTrace) -> None:
        """Begin with the rows of `earlier` (a reasoning continued in a new engine)."""
        self.node_rows, self.edge_rows = list(earlier.node_rows), list(earlier.edge_rows)
        self.node_bounds, self.edge_bounds = list(earlier.node_bounds), list(earlier.edge_bounds)
        self.clauses = dict(earlier.clauses)

    def _pred(self, tl: str) -> str:
        return self.names.original_predicate(tl)

    @staticmethod
    def _component(args: tuple[str, ...]) -> str | tuple[str, ...]:
        """A node as its id, an edge as a tuple (written as Python writes it: `('a', 'b')`)."""
        return args[0] if len(args) == 1 else tuple(args)

    def add(self, rows: dict[str, np.ndarray], passes_before: int, t: int | None = None) -> None:
        """One step's rows (Engine.take_trace()); `passes_before`: ordinary passes of the earlier steps;
        `t`: the step (needed for the rows of facts that conflict from [0,1], which the engine does not
        write). Within a step's pass the rows come in PyReason's order: facts first, then each rule's in
        rule order, a rule's heads in the graph's node order (PyReason's example trace: John before
        Justin). An atom several facts set in the step has a row per fact (fact_sequence.py)."""
        eng = self.engine
        cols = {k: v.tolist() for k, v in rows.items()}
        step: list[tuple[tuple[int, ...], str, list[object], tuple[float, float]]] = []
        several = self._several_facts(t if t is not None else (int(cols["t"][0]) if cols["t"] else -1))
        conflicts = self._rule_conflicts(cols)
        for i in range(len(cols["t"])):
            if int(cols["world"][i]) != 0:
                continue
            kind, cid, g = int(cols["cause_kind"][i]), int(cols["cause_id"][i]), int(cols["grounding"][i])
            atom = int(cols["atom"][i])
            if atom in several and int(cols["pass_no"][i]) == 0 and g < 0 and kind in (CAUSE_FACT, CAUSE_POLICY):
                old, new = (cols["old_lower"][i], cols["old_upper"][i]), (cols["new_lower"][i], cols["new_upper"][i])
                if self._fact_rows(step, atom, several.pop(atom), old, new, int(cols["t"][i]), passes_before, i):
                    continue
            graph_fact = kind == CAUSE_FACT and cid < self.graph_facts
            if kind == CAUSE_RESET or (graph_fact and self.skip_graph_facts):
                continue
            pred, args = eng.vocab.atom_parts(int(cols["atom"][i]))
            if pred == DOMAIN:  # the translation's own (translate.DOMAIN), not PyReason's
                continue
            rule_no = -1
            old = _bound(cols["old_lower"][i], cols["old_upper"][i])
            consistent = kind != CAUSE_POLICY
            if kind == CAUSE_RULE or (kind == CAUSE_POLICY and g >= 0):
                rule_no = int(eng.groundings.rule[g]) if g >= 0 else cid
                rule = eng.rules[rule_no]
                due, by = self.names.original_statement(rule.name), "Rule"
                if rule.name in self.ipl_rules:  # PyReason's names for what its IPL sets
                    due, by = f"IPL: {self.ipl_rules[rule.name]}", "IPL"
                    partner = (int(cols["pass_no"][i]), self.ipl_partners.get(self._pred(pred)), args)
                    if kind == CAUSE_POLICY and partner in conflicts:  # PyReason resets the partner of an
                        rule_no = conflicts[partner]  # atom a rule's update conflicts on, naming that rule
                        rule = eng.rules[rule_no]
                        due = self.names.original_statement(rule.name)
            elif graph_fact:
                due, by = GRAPH_ATTRIBUTE_FACT, "Fact"
            elif kind == CAUSE_FACT and eng.fact(cid).name in self.ipl_facts:  # a fact's IPL partner
                due, by = f"IPL: {self.ipl_facts[eng.fact(cid).name][0]}", "IPL"
            elif kind == CAUSE_FACT:
                due, by = self.names.original_statement(eng.fact(cid).name), "Fact"
            elif kind == CAUSE_EXTERNAL and cid in self.external_names:
                due, by = self.external_names[cid], "Fact"
            else:
                due, by = "-", "Fact"
            message = "" if consistent else self._inconsistency(pred, args, old, rule if rule_no >= 0 else None,
                                                                by == "IPL")
            row: list[object] = [int(cols["t"][i]), passes_before + int(cols["pass_no"][i]),
                                 self._component(args), self._pred(pred), old,
                                 _bound(cols["new_lower"][i], cols["new_upper"][i]), due, consistent, by, message]
            if g >= 0 and by != "IPL":  # PyReason's IPL rows have no clauses
                parts = [eng.vocab.atom_parts(int(a)) for a in eng.groundings.body(g)]
                row += [[self._component(a)] for p, a in parts if p != DOMAIN]
            which = "node" if len(args) == 1 else "edge"
            self.clauses[which] = max(self.clauses[which], len(row) - len(NODE_HEADER))
            # facts in the program's order; a rule's heads in node order, its IPL twin's row right after it
            heads = ([eng.vocab.node_ids[a] for a in args] if rule_no >= 0 else
                     [cid] if kind == CAUSE_FACT else [len(eng.program.facts) + i])
            twin = rule_no >= 0 and rule.name in self.ipl_twin_rules
            ordered_no = self._rule_number(self.ipl_twin_rules[rule.name]) if twin else rule_no
            order = (int(cols["t"][i]), int(cols["pass_no"][i]), ordered_no, *heads, int(by == "IPL"))
            step.append((order, which, row, (float(cols["new_lower"][i]), float(cols["new_upper"][i]))))
        for atom, facts in several.items():  # no row: from [0,1], a conflict leaves [0,1]
            if t is not None and self.engine.static[0, atom] and self.engine.bound(atom) == (0.0, 1.0):
                self._fact_rows(step, atom, facts, (0.0, 1.0), (0.0, 1.0), t, passes_before, -1)
        if t is not None:
            self._delayed_conflicts(step, t, passes_before)
            self._facts_on_frozen_atoms(step, t, passes_before)
        self.static_before = eng.static[0].copy()
        step.sort(key=lambda r: r[0])  # stable: a fact's rows, and one rule's rows on one head, keep theirs
        for _, which, row, bound in step:
            (self.node_rows if which == "node" else self.edge_rows).append(row)
            (self.node_bounds if which == "node" else self.edge_bounds).append(bound)

    def _facts_by_atom(self) -> dict[int, list[tuple[int, int, StepFact]]]:
        """The program's facts (not the graph's) by atom: (start, end, fact), in the facts' order. Only
        under PyReason's default policy (reset to [0,1], frozen), the one fact_sequence.py follows."""
        if self._facts is None:
            eng, by_atom = self.engine, {}
            if eng.program.inconsistency == "reset_freeze":
                for k, f in enumerate(eng.program.facts, start=eng.graph.n_facts):  # k: the fact's id (Engine.fact)
                    lit = f.literal
                    atom = eng.atom(lit.pred, *(a.name for a in lit.args))
                    lo, up = effective_bound(lit.lower, lit.upper, lit.negated)
                    name = self.names.original_statement(f.name)
                    if f.name in self.ipl_facts:  # PyReason's rows of the partner a fact's IPL sets
                        src, of = self.ipl_facts[f.name]
                        fact = StepFact(f"IPL: {src}", lo, up, k, "IPL", of, src)
                    else:
                        fact = StepFact(name, lo, up, k, "Fact", "", self._pred(lit.pred))
                    by_atom.setdefault(atom, []).append((f.start, f.end, fact))
            self._facts = by_atom
        return self._facts

    def _facts_at(self, atom: int, t: int) -> list[StepFact]:
        return [f for start, end, f in self._facts_by_atom().get(atom, []) if start <= t <= end]

    def _several_facts(self, t: int) -> dict[int, list[StepFact]]:
        """The atoms two or more facts set at step t (and no conflict froze before), with those facts."""
        out = {}
        for atom in self._facts_by_atom():
            now = self._facts_at(atom, t)
            if len(now) > 1 and atom not in self.frozen and not self._was_static(atom):
                out[atom] = now
        return out

    def _was_static(self, atom: int) -> bool:
        """Whether `atom` was frozen when the step began (by a conflict, a static fact or rule)."""
        return self.static_before is not None and atom < len(self.static_before) and bool(self.static_before[atom])

    def _facts_on_frozen_atoms(self, step: list, t: int, passes_before: int) -> None:
        """PyReason's rows of the step's facts on atoms frozen before it (fact_sequence.on_frozen_atom),
        each followed by its IPL partner's row (the partner's bound as old and new, `Occurred Due To` the
        fact, as PyReason's committed cybersecurity trace: `vulnerable(web_server)` [0,1] -> [0,1] by
        patch_db_fact). The engine writes no row: the atom does not change."""
        eng = self.engine
        for atom in self._facts_by_atom():
            if not self._was_static(atom):
                continue
            pred, args = eng.vocab.atom_parts(atom)
            which = "node" if len(args) == 1 else "edge"
            for r in on_frozen_atom(self._facts_at(atom, t)):
                fact = r.fact
                assert fact is not None
                row: list[object] = [t, passes_before, self._component(args), fact.pred, _bound(*r.old),
                                     _bound(*r.new), r.name, True, "Fact", ""]
                step.append(((t, 0, -1, fact.order, 0), which, row, r.new))
                partner_name = self.ipl_partners.get(fact.pred)
                partner_tl = self.names.pred_to_tl.get((partner_name, len(args))) if partner_name else None
                if partner_tl is None:
                    continue
                partner = eng.atom(partner_tl, *args)
                if self._was_static(partner):  # a frozen partner keeps its bound through the step
                    bound = eng.bound(partner)
                    row = [t, passes_before, self._component(args), partner_name, _bound(*bound), _bound(*bound),
                           r.name, True, "IPL", ""]
                    step.append(((t, 0, -1, fact.order, 1), which, row, bound))

    def _fact_rows(self, step: list, atom: int, facts: list[StepFact], old: tuple[float, float],
                   new: tuple[float, float], t: int, passes_before: int, i: int) -> bool:
        """PyReason's rows of `facts` applied one by one to `atom` (from `old`), into `step`, when they
        end where the engine did (`new`); else False and nothing added."""
        rows, end = applied_one_by_one(old, facts)
        if end != new:
            return False
        pred, args = self.engine.vocab.atom_parts(atom)
        which = "node" if len(args) == 1 else "edge"
        for k, r in enumerate(rows):
            fact = r.fact
            assert fact is not None
            message = ""
            if not r.consistent and fact.pred in self.ipl_partners:  # PyReason names the IPL's two groundings
                message = self._ipl_message(fact.pred, self.ipl_partners[fact.pred], args)
            elif not r.consistent:
                message = conflict_message(f"{self._pred(pred)}({','.join(args)})", r.old, r.incoming)
            if not r.consistent:
                self.frozen.add(atom)
            row: list[object] = [t, passes_before, self._component(args), self._pred(pred), _bound(*r.old),
                                 _bound(*r.new), r.name, r.consistent, fact.by, message]
            step.append(((t, 0, -1, fact.order, k), which, row, r.new))
        return True

    def _delayed_conflicts(self, step: list, t: int, passes_before: int) -> None:
        """PyReason's rows of a delayed rule's firing that contradicts a fact's IPL partner: both land in
        pass 0 of a step that began at [0,1], so the engine resets the pair without a row. Rows: the facts
        (and the partners they set), then the rule's head reset and its partner's, named by the delayed
        rule with that head predicate (without clauses: the engine keeps no row of which grounding)."""
        eng, seen = self.engine, {repr(row[2:4]) for _, _, row, _ in step if row[0] == t}
        delayed = {self._pred(r.head.pred): k
                   for k, r in reversed(list(enumerate(eng.rules)))
                   if r.delay > 0 and r.name not in self.ipl_rules}
        for atom in np.flatnonzero(eng.static[0]):
            atom = int(atom)
            pred, args = eng.vocab.atom_parts(atom)
            name = self._pred(pred)
            partner_name = self.ipl_partners.get(name)
            if name not in delayed or partner_name is None or atom in self.frozen or eng.bound(atom) != (0.0, 1.0):
                continue
            partner_tl = self.names.pred_to_tl.get((partner_name, len(args)))
            partner = eng.atom(partner_tl, *args) if partner_tl is not None else None
            if partner is None or partner >= eng.static.shape[1] or not eng.static[0, partner] or eng.bound(partner) != (0.0, 1.0) \
                    or repr([self._component(args), name]) in seen:
                continue
            fact_rows, ends = [], {}
            for a in (atom, partner):
                rows, ends[a] = applied_one_by_one((0.0, 1.0), self._facts_at(a, t))
                if any(not r.consistent for r in rows):
                    break
                fact_rows += rows
            else:
                which = "node" if len(args) == 1 else "edge"
                for k, r in enumerate(sorted(fact_rows, key=lambda r: r.fact.order)):
                    a_name = r.fact.pred if r.fact.by == "Fact" else self.ipl_partners[r.fact.pred]
                    row = [t, passes_before, self._component(args), a_name, _bound(*r.old), _bound(*r.new),
                           r.name, True, r.fact.by, ""]
                    step.append(((t, 0, -1, r.fact.order, k), which, row, r.new))
                rule_no = delayed[name]
                due = self.names.original_statement(eng.rules[rule_no].name)
                if due in self.ipl_twin_rules:
                    due = self.ipl_twin_rules[due]
                message = self._ipl_message(name, partner_name, args)
                heads = [eng.vocab.node_ids[a] for a in args]
                for sub, (a, label, by) in enumerate(((atom, name, "Rule"), (partner, partner_name, "IPL"))):
                    row = [t, passes_before, self._component(args), label, _bound(*ends[a]), _bound(0.0, 1.0), due,
                           False, by, message]
                    step.append(((t, 0, rule_no, *heads, sub), which, row, (0.0, 1.0)))
                self.frozen.update((atom, partner))

    def _rule_conflicts(self, cols: dict[str, list]) -> dict[tuple[int, str, tuple[str, ...]], int]:
        """(pass, PyReason predicate, args) -> the rule (not the IPL's) whose update conflicted there."""
        out = {}
        for i in range(len(cols["t"])):
            g = int(cols["grounding"][i])
            if int(cols["world"][i]) == 0 and int(cols["cause_kind"][i]) == CAUSE_POLICY and g >= 0:
                rule_no = int(self.engine.groundings.rule[g])
                if self.engine.rules[rule_no].name not in self.ipl_rules:
                    pred, args = self.engine.vocab.atom_parts(int(cols["atom"][i]))
                    out[(int(cols["pass_no"][i]), self._pred(pred), args)] = rule_no
        return out

    def _rule_number(self, name: str) -> int:
        """The engine's index of the rule PyReason names `name`."""
        if self._rule_numbers is None:
            self._rule_numbers = {}
            for k, r in enumerate(self.engine.rules):
                self._rule_numbers.setdefault(self.names.original_statement(r.name), k)
        return self._rule_numbers.get(name, -1)

    @staticmethod
    def _ipl_message(pred: str, partner: str, args: tuple[str, ...]) -> str:
        comp = ",".join(args)
        return (f"Inconsistency occurred. Grounding {pred}({comp}) conflicts with grounding {partner}({comp}). "
                "Setting bounds to [0,1] and static=True for this timestep.")

    def _inconsistency(self, pred: str, args: tuple[str, ...], old: str, rule: Any, partner_row: bool) -> str:
        """PyReason's message of the conflict `rule` (None: a fact) caused on pred(args): a predicate of the
        IPL names both groundings, the conflicting update's first (on the partner's row, the other); else
        the bounds."""
        name = self._pred(pred)
        if partner_row and name in self.ipl_partners:
            return self._ipl_message(self.ipl_partners[name], name, args)
        if name in self.ipl_partners:
            return self._ipl_message(name, self.ipl_partners[name], args)
        atom = f"{name}({','.join(args)})"
        if rule is not None and rule.annotation is None:  # PyReason quotes both bounds
            lo, up = effective_bound(rule.head.lower, rule.head.upper, rule.head.negated)
            return conflict_message(atom, tuple(float(v) for v in old.strip("[]").split(",")), (lo, up))
        return (f"Inconsistency occurred. Conflicting bounds for {atom}. Update from {old} is not allowed. "
                "Setting bounds to [0,1] and static=True for this timestep.")

    def layout(self, which: str, atom_trace: bool = True) -> tuple[list[str], list[list[object]]]:
        """The header and rows of the nodes' or edges' trace as PyReason's Output makes them. With
        atom_trace (PyReason's setting) the rows as collected, clause columns padded with None; without it
        (PyReason's default) its short layout: Old Bound '-', no clause columns, no inconsistency message,
        Occurred Due To '-' except a consistent IPL row's `IPL: <the predicate whose update set it>`."""
        header, rows = (NODE_HEADER, self.node_rows) if which == "nodes" else (EDGE_HEADER, self.edge_rows)
        if not atom_trace:
            return list(header), [r[:4] + ["-", r[5], self._short_due(r), r[7], r[8], ""] for r in rows]
        n = self.clauses["node" if which == "nodes" else "edge"]
        cols = header + [f"Clause-{k}" for k in range(1, n + 1)]
        return cols, [r + [None] * (len(cols) - len(r)) for r in rows]

    def _short_due(self, row: list[object]) -> object:
        """Occurred Due To without atom_trace: PyReason keeps a name there only on a consistent IPL row."""
        if row[8] != "IPL" or not row[7]:
            return "-"
        partner = self.ipl_partners.get(str(row[3]))
        return f"IPL: {partner}" if partner is not None else row[6]

    def write(self, folder: str | os.PathLike[str], timestamp: str | None = None,
              atom_trace: bool = True) -> tuple[str, str]:
        """rule_trace_nodes_<timestamp>.csv and rule_trace_edges_<timestamp>.csv in `folder` (created)."""
        os.makedirs(folder, exist_ok=True)
        stamp = timestamp or time.strftime("%Y%m%d-%H%M%S")
        paths = []
        for which in ("nodes", "edges"):
            header, rows = self.layout(which, atom_trace)
            path = os.path.join(os.fspath(folder), f"rule_trace_{which}_{stamp}.csv")
            with open(path, "w", newline="", encoding="utf-8") as f:
                w = csv.writer(f, lineterminator="\n")
                w.writerow(header)
                w.writerows([["" if v is None else v for v in r] for r in rows])
            paths.append(path)
        return paths[0], paths[1]
