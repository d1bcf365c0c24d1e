"""A run's program and vocabulary as read back from the store, for the commands that reason about it
(why, why-not, diff): rules with their clauses, fact and policy names, nodes, labels and atom lookups."""
from __future__ import annotations

import re
from collections.abc import Iterable
from typing import Any, NamedTuple

from tracelab.engine.errors import ProgramError
from tracelab.engine.bounds import satisfies as engine_satisfies
from tracelab.engine.spelling import CONSTANT_RE, PREDICATE_RE
from tracelab.store.kind import run_config
from tracelab.store.names import UnknownName, unknown_name_message
from tracelab.store.reader import RunConnection

DEFAULT_BOUND = (0.0, 1.0)  # an atom never set
# deferred: the engine's parser (it loads numpy) reads an atom only when it is not written as the store
# writes atoms, label(a,b) of plain constants (RunModel.parse_atom): `why ATOM` on such an atom needs neither
_C = CONSTANT_RE.pattern
_PLAIN_ATOM = re.compile(rf"[ \t]*({PREDICATE_RE.pattern})\([ \t]*({_C})(?:[ \t]*,[ \t]*({_C}))?[ \t]*\)[ \t]*")


class Clause(NamedTuple):
    label: str
    args: tuple[str, ...]
    is_var: tuple[bool, ...]
    negated: bool
    lower: float
    upper: float
    text: str
    closed: bool = False  # `%closed` predicate: an atom never set ([0,1]) reads as [0,0]

    @property
    def binds(self) -> bool:
        """Whether the clause can enumerate its variables: false when it holds of an atom never set
        (its bound contains [0,1], or, closed, it holds of [0,0])."""
        if self.lower <= 0.0 and self.upper >= 1.0:
            return False
        return not (self.closed and satisfies((0.0, 0.0), self))

    def variables(self) -> tuple[str, ...]:
        return tuple(a for a, v in zip(self.args, self.is_var) if v)

    def ground_text(self, binding: dict[str, str]) -> str:
        args = ",".join(binding.get(a, a) if v else a for a, v in zip(self.args, self.is_var))
        return f"{'~' if self.negated else ''}{self.label}({args}):[{self.lower:g},{self.upper:g}]"


class RuleInfo(NamedTuple):
    rule: int
    name: str
    delay: int
    immediate: bool
    variables: tuple[str, ...]
    text: str
    head: Clause
    body: list[Clause]


def satisfies(bound: tuple[float, float], clause: Clause) -> bool:
    """I ⊨ clause (the engine's own test, tracelab.engine.program.satisfies, on a stored clause; a
    closed clause reads [0,1] as [0,0], as the engine does)."""
    return engine_satisfies(bound[0], bound[1], clause, clause.closed)  # type: ignore[arg-type]


def external_causes(config: dict[str, Any]) -> dict[str, str]:
    """What set each predicate of a declared world's external facts, from its run's config
    (tracelab.envs.declared.recording.declared_facts): `action`, `draw:NAME`, `env` (computed each step);
    {} for a run that does not say (every external fact then reads `action`)."""
    declared = config.get("declared_facts")
    if not isinstance(declared, dict):
        return {}
    names: dict[str, str] = {}
    for pred in declared.get("computed") or ():
        names[str(pred)] = "env"
    draws = declared.get("draws")
    for draw, preds in (draws.items() if isinstance(draws, dict) else ()):
        for pred in preds if isinstance(preds, list) else ():
            names[str(pred)] = f"draw:{draw}"
    for pred in declared.get("actions") or ():
        names[str(pred)] = "action"
    return names


class RunModel:
    def __init__(self, con: RunConnection) -> None:
        self.con = con
        self.rules: list[RuleInfo] = []
        rules = con.execute("SELECT rule, name, delay, immediate, variables, text FROM raw.rules "
                            "ORDER BY rule").fetchall()
        clauses: dict[int, list[tuple]] = {}
        for row in con.execute("SELECT rule, pos, label, args, is_var, negated, lower, upper, text, closed "
                               "FROM raw.clauses ORDER BY rule, pos").fetchall():
            clauses.setdefault(row[0], []).append(row)
        for rid, name, delay, immediate, variables, text in rules:
            cl = [Clause(r[2], tuple(r[3]), tuple(r[4]), r[5], r[6], r[7], r[8], bool(r[9]))
                  for r in clauses.get(rid, [])]
            self.rules.append(RuleInfo(rid, name, delay, immediate, tuple(variables or ()), text,
                                       head=cl[0], body=cl[1:]))
        self.rule_by_name = {r.name: r for r in self.rules}
        self._facts: dict[int, tuple[str, str]] | None = None   # read on first use: few explanations name one
        self._policies: dict[int, str] | None = None
        self._external: dict[str, str] | None = None
        # nodes, labels and atoms: read together on first use (_read_atoms), so that every atom's nodes and
        # label are among those read (a live run's vocabulary grows)
        self._nodes: list[str] = []
        self._node_ids: dict[str, int] = {}
        self._labels: dict[str, tuple[int, int]] = {}
        self._vocabulary_read = False
        self._atom_text: dict[int, str] = {}
        self._atom_keys: list[tuple[int, int, int] | None] = []  # per atom id: (label, arg0, arg1 or -1)
        self._label_names: dict[int, str] = {}
        self._atom_ids: dict[tuple[int, int, int], int] = {}
        self._groundings: dict[int, tuple[int, list[int], list[int]]] = {}

    @property
    def facts(self) -> dict[int, tuple[str, str]]:
        """{fact id: (name, literal)}."""
        if self._facts is None:
            self._facts = {f: (n, t) for f, n, t in
                           self.con.execute("SELECT fact, name, literal FROM raw.facts").fetchall()}
        return self._facts

    @property
    def policies(self) -> dict[int, str]:
        """{policy code: name}."""
        if self._policies is None:
            self._policies = dict(self.con.execute("SELECT code, name FROM raw.policies").fetchall())
        return self._policies

    @property
    def external(self) -> dict[str, str]:
        """external_causes of the run's config, read when a row set by an action is first named."""
        if self._external is None:
            self._external = external_causes(run_config(self.con))
        return self._external

    @property
    def nodes(self) -> list[str]:
        """Node names by node id."""
        if not self._vocabulary_read:
            self._read_atoms()
        return self._nodes

    @property
    def node_ids(self) -> dict[str, int]:
        if not self._vocabulary_read:
            self._read_atoms()
        return self._node_ids

    @property
    def labels(self) -> dict[str, tuple[int, int]]:
        """{label name: (label id, arity)}."""
        if not self._vocabulary_read:
            self._read_atoms()
        return self._labels

    # ---- rules -----------------------------------------------------------------------------------------
    def rule(self, name: str) -> RuleInfo:
        r = self.rule_by_name.get(name)
        if r is None:
            raise UnknownName(unknown_name_message("rule", name, list(self.rule_by_name)))
        return r

    def cause_name(self, kind: int, cid: int) -> str:
        """The `rule` column of the changes view: rule name, fact:NAME, action, policy:NAME, reset."""
        if kind == 0:
            return f"fact:{self.facts.get(cid, (str(cid),))[0]}"
        if kind == 1:
            return "action"
        if kind == 2:
            return self.rules[cid].name if 0 <= cid < len(self.rules) else f"rule#{cid}"
        if kind == 3:
            return f"policy:{self.policies.get(cid, cid)}"
        return "reset"

    # ---- groundings ------------------------------------------------------------------------------------
    def grounding(self, g: int) -> tuple[int, list[int], list[int]]:
        """(rule id, body atom ids in clause order, variable values as node ids)."""
        if g not in self._groundings:
            # fetchall, not fetchone: DuckDB 2.0 refuses the connection's next statement while a result
            # is not read to its end
            rows = self.con.execute("SELECT rule, body_atoms, var_values FROM raw.groundings "
                                    "WHERE grounding = ?", [g]).fetchall()
            row = rows[0] if rows else None
            if row is None:
                raise KeyError(f"grounding {g} is not in the run's grounding table")
            self._groundings[g] = (row[0], list(row[1]), list(row[2]))
        return self._groundings[g]

    def prefetch_groundings(self, ids: Iterable[int]) -> None:
        """Read these groundings in one query (callers about to explain many rows of an episode)."""
        wanted = {int(g) for g in ids if g >= 0}
        missing = sorted(wanted - self._groundings.keys())
        if missing:
            for g, rule, body, values in self.con.execute(
                    "SELECT grounding, rule, body_atoms, var_values FROM raw.groundings "
                    "WHERE grounding IN (SELECT unnest(?::INTEGER[]))", [missing]).fetchall():
                self._groundings[g] = (rule, list(body), list(values))

    def bindings(self, g: int) -> dict[str, str]:
        rule, _, values = self.grounding(g)
        return {v: self.nodes[x] for v, x in zip(self.rules[rule].variables, values)}

    # ---- atoms -------------------------------------------------------------------------------------------
    def atom_texts(self, ids: Iterable[int]) -> dict[int, str]:
        """label(arg0[,arg1]) of atom ids, as the atoms view writes them; built from the atoms table read
        once (again when an id is past it: a live run's vocabulary grows), not a query per call."""
        out = {}
        for a in (int(x) for x in ids):
            text = self._atom_text.get(a)
            if text is None:
                if a >= len(self._atom_keys):
                    self._read_atoms()
                key = self._atom_keys[a] if 0 <= a < len(self._atom_keys) else None
                if key is None:
                    text = f"atom#{a}"
                else:
                    args = [self.nodes[n] for n in key[1:] if n >= 0]
                    text = f"{self._label_names.get(key[0], '?')}({','.join(args)})"
                self._atom_text[a] = text
            out[a] = text
        return out

    def _read_atoms(self) -> None:
        rows = self.con.execute("SELECT atom, label, arg0, arg1 FROM raw.atoms").fetchall()
        keys: list[tuple[int, int, int] | None] = [None] * (max((r[0] for r in rows), default=-1) + 1)
        for atom, label, arg0, arg1 in rows:
            keys[atom] = (label, arg0, -1 if arg1 is None else arg1)
        self._atom_keys = keys
        self._vocabulary_read = True
        self._nodes = [n for (n,) in self.con.execute("SELECT name FROM raw.nodes ORDER BY node").fetchall()]
        self._node_ids = {n: i for i, n in enumerate(self._nodes)}
        self._labels = {name: (lid, arity) for lid, name, arity in
                        self.con.execute("SELECT label, name, arity FROM raw.labels").fetchall()}
        self._label_names = {lid: name for name, (lid, _) in self._labels.items()}
        self._atom_ids = {key: a for a, key in enumerate(keys) if key is not None}

    def atom_text(self, aid: int) -> str:
        return self.atom_texts([aid])[aid]

    def label_id(self, label: str, arity: int) -> int:
        if label not in self.labels:
            raise UnknownName(unknown_name_message("label", label, list(self.labels)))
        lid, have = self.labels[label]
        if have != arity:
            raise KeyError(f"label {label!r} has arity {have}, not {arity}")
        return lid

    def node_id(self, name: str) -> int:
        if name not in self.node_ids:
            raise UnknownName(unknown_name_message("node", name, self.nodes))
        return self.node_ids[name]

    def find_atom(self, label: str, args: tuple[str, ...]) -> int | None:
        """The atom id of label(args), or None if it was never interned (then it is [0,1])."""
        if label not in self.labels or any(a not in self.node_ids for a in args):
            return None
        key = (self.labels[label][0], self.node_ids[args[0]], self.node_ids[args[1]] if len(args) > 1 else -1)
        if key not in self._atom_ids and self._vocabulary_grew():
            self._read_atoms()         # built once from the atoms table; again for a grown vocabulary
        return self._atom_ids.get(key)

    def _vocabulary_grew(self) -> bool:
        if not self._atom_keys:
            return True
        rows = self.con.execute("SELECT max(atom) FROM raw.atoms").fetchall()
        return rows[0][0] is not None and rows[0][0] >= len(self._atom_keys)

    def parse_atom(self, text: str) -> int:
        """The id of a ground atom written as text, e.g. atLoc(red-agent-1,16); errors name what is missing."""
        plain = _PLAIN_ATOM.fullmatch(text)
        if plain:  # what the parser reads it as, without loading it
            label, args = plain[1], tuple(a for a in plain.groups()[1:] if a is not None)
        else:
            from tracelab.engine.parser import parse_literal
            try:
                lit = parse_literal(text)
            except ProgramError as e:
                raise ValueError(f"cannot read atom {text!r}: {e}") from None
            if any(t.is_var for t in lit.args):
                raise ValueError(f"atom {text!r} is not ground")
            label, args = lit.pred, tuple(t.name for t in lit.args)
        self.label_id(label, len(args))
        for a in args:
            self.node_id(a)
        aid = self.find_atom(label, args)
        if aid is None:
            raise KeyError(f"atom {text!r} never occurs in this run (its label and nodes do)")
        return aid

    def atoms_matching(self, label: str, pattern: tuple[str | None, ...]) -> list[tuple[int, tuple[str, ...]]]:
        """Atoms of `label` whose arguments equal the non-None entries of `pattern`, with their args,
        ordered by node ids (then atom id: a total order)."""
        if label not in self.labels:
            return []
        lid = self.labels[label][0]
        sql = "SELECT atom, arg0, arg1 FROM raw.atoms WHERE label = ?"
        params: list[int] = [lid]
        for pos, value in enumerate(pattern):
            if value is not None:
                if value not in self.node_ids:
                    return []
                sql += f" AND arg{pos} = ?"
                params.append(self.node_ids[value])
        rows = self.con.execute(sql + " ORDER BY arg0, arg1, atom", params).fetchall()
        return [(aid, (self.nodes[a0],) if a1 < 0 else (self.nodes[a0], self.nodes[a1]))
                for aid, a0, a1 in rows]
