"""Explanations read from a stored trace.

why(atom, t): the change row that set the atom's bound in force at the end of t; its cause (rule, fact,
agent action, policy, reset); for a rule, the ground body atoms its grounding used and, recursively, why
each held when the rule read it: just before the row for an immediate rule, before the ordinary pass for
other Δt=0 rules, at the end of t−Δt for delayed rules. Leaves: facts, actions (external facts), resets,
atoms never set ([0,1]), and the depth limit. why of a change (explain_change): the same tree rooted at
one given change row, for an atom that changed more than once within t.

why-not(rule, bindings, t): the rule's body clauses checked in order at the time the rule would have read
them (the end of t−Δt; the end of t for Δt=0) under the given bindings, extending them through the
atoms of the vocabulary for unbound variables; reports the first clause that could not be satisfied."""
from __future__ import annotations

import re
from typing import Any, NamedTuple

from tracelab.store.coordinates import Grid
from tracelab.store.episode import EpisodeTrace, Row
from tracelab.store.model import Clause, RuleInfo, RunModel, satisfies
from tracelab.store.reader import RunConnection
from tracelab.store.schema import CAUSE_NAMES


def parse_bindings(text: str) -> dict[str, str]:
    """`A=red-agent-1,X=c3_1` as {variable: value} (why-not's --grounding, the TUI's why-not line); raises
    ValueError naming the part it cannot read."""
    out: dict[str, str] = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        var, eq, value = part.partition("=")
        if not eq or not var.strip() or not value.strip():
            raise ValueError(f"cannot read binding {part!r}; write VAR=value, e.g. A=red-agent-1")
        out[var.strip()] = value.strip()
    return out


def _bound_text(b: tuple[float, float] | list[float] | None) -> str:
    return "?" if b is None else f"[{b[0]:g},{b[1]:g}]"


# The records below are plain classes and NamedTuples, not dataclasses: a dataclass costs ~1-2 ms of CPU to
# create at import, a good part of what `why` adds to DuckDB's own start-up (issue 40). to_dict() gives the
# fields in the order written, as --json prints them.

class Cause:
    def __init__(self, kind: str, name: str, grounding: int = -1, reads: str = "") -> None:
        self.kind = kind                        # rule | fact | action | policy | reset | default
        self.name = name                        # as in the changes view's `rule` column ('' for default)
        self.grounding = grounding
        self.bindings: dict[str, str] = {}
        self.delay: int | None = None
        self.immediate: bool | None = None
        self.reads = reads                      # when the body was read
        self.text = ""                          # the rule's or fact's source text

    def to_dict(self) -> dict[str, Any]:
        return {**vars(self), "bindings": dict(self.bindings)}


class WhyNode:
    def __init__(self, atom: str, value: list[float], clause: str | None = None, holds: bool | None = None,
                 clause_closed: bool = False) -> None:
        self.atom = atom
        self.value = value                      # the bound in force at the point read
        self.clause = clause                    # the ground body clause this node supports (None at the root)
        self.holds = holds                      # does `value` satisfy `clause`
        self.clause_closed = clause_closed      # `clause` is on a %closed predicate: [0,1] reads as [0,0]
        self.t: int | None = None               # the change that set the value (None: never set)
        self.pass_no: int | None = None
        self.seq: int | None = None
        self.old: list[float] | None = None
        self.cause: Cause | None = None
        self.children: list[WhyNode] = []
        self.truncated = False                  # the depth limit stopped the explanation here
        self.repeated = False                   # the same change is explained higher up the tree

    def to_dict(self) -> dict[str, Any]:
        return {**vars(self), "value": list(self.value), "old": None if self.old is None else list(self.old),
                "cause": None if self.cause is None else self.cause.to_dict(),
                "children": [c.to_dict() for c in self.children]}


def set_by(model: RunModel, row: Row) -> str:
    """The name of what set `row` (its rule, fact:NAME, ...); an external fact of a declared world by
    what set its predicate (external_causes), `start` for the start facts no action, draw or computation sets."""
    if row.cause_kind == 1 and model.external:
        return model.external.get(model.atom_text(row.atom).split("(", 1)[0], "start")
    return model.cause_name(row.cause_kind, row.cause_id)


class _Explainer:
    def __init__(self, model: RunModel, trace: EpisodeTrace) -> None:
        self.m = model
        self.tr = trace
        self.immediate = {r.rule for r in model.rules if r.immediate}
        self.seen: set[int] = set()

    def node(self, atom: int, row: Row | None, depth: int, clause: Clause | None = None,
             binding: dict[str, str] | None = None) -> WhyNode:
        value = EpisodeTrace.bound(row)
        n = WhyNode(atom=self.m.atom_text(atom), value=list(value),
                    clause=None if clause is None else clause.ground_text(binding or {}),
                    holds=None if clause is None else satisfies(value, clause),
                    clause_closed=clause is not None and clause.closed)
        if row is None:
            n.cause = Cause("default", "", reads="never set: [0,1]")
            return n
        n.t, n.pass_no, n.seq, n.old = row.t, row.pass_no, row.seq, list(row.old)
        n.cause = self._cause(row)
        if row.seq in self.seen:
            n.repeated = True
            return n
        self.seen.add(row.seq)
        rule = self._rule_of(row)
        if rule is None:
            return n
        if depth <= 0:
            n.truncated = True
            return n
        _, body_atoms, _ = self.m.grounding(row.grounding)
        self.m.atom_texts(body_atoms)
        binding = n.cause.bindings
        reads = [self._read(rule, row, aid) for aid in body_atoms]
        # the children's groundings in one query, not one each
        self.m.prefetch_groundings(r.grounding for r in reads if r is not None and r.cause_kind in (2, 3))
        for clause_i, aid, read in zip(rule.body, body_atoms, reads):
            n.children.append(self.node(aid, read, depth - 1, clause_i, binding))
        return n

    def _rule_of(self, row: Row) -> RuleInfo | None:
        if row.grounding < 0 or row.cause_kind not in (2, 3):
            return None
        return self.m.rules[self.m.grounding(row.grounding)[0]]

    def _read(self, rule: RuleInfo, row: Row, atom: int) -> Row | None:
        if rule.delay > 0:
            return self.tr.last_at_end_of(atom, row.t - rule.delay)
        if rule.immediate:
            return self.tr.last_before(atom, row.index)
        return self.tr.last_before(atom, self.tr.ordinary_pass_start(row.index, self.immediate))

    def _cause(self, row: Row) -> Cause:
        kind = CAUSE_NAMES.get(row.cause_kind, str(row.cause_kind))
        c = Cause(kind, set_by(self.m, row), grounding=row.grounding)
        if row.cause_kind == 0:
            c.text = self.m.facts.get(row.cause_id, ("", ""))[1]
        rule = self._rule_of(row)
        if rule is not None:
            c.bindings = self.m.bindings(row.grounding)
            c.delay, c.immediate, c.text = rule.delay, rule.immediate, rule.text
            if rule.delay > 0:
                c.reads = f"body read at the end of t={row.t - rule.delay}"
            elif rule.immediate:
                c.reads = "body read just before this application"
            else:
                c.reads = f"body read before ordinary pass {row.pass_no} of t={row.t}"
            if row.cause_kind == 3:
                c.reads += f"; first incoming source: {rule.name}"
        return c


def _check_episode(con: RunConnection, episode: int, trace: EpisodeTrace) -> None:
    if trace.n == 0:
        known = [e for (e,) in con.execute(
            "SELECT DISTINCT episode FROM raw.changes ORDER BY episode LIMIT 20").fetchall()]
        raise KeyError(f"episode {episode} has no trace rows at or before that time "
                       f"(episodes with rows: {known if known else 'none'})")


def episode_at(con: RunConnection, episode: int, at: int) -> tuple[RunModel, EpisodeTrace]:
    """The run's model and the episode's rows up to the end of timestep `at`: what explaining reads."""
    model = RunModel(con)
    trace = EpisodeTrace(con, episode, upto_t=at)
    _check_episode(con, episode, trace)
    return model, trace


def explain(con: RunConnection, episode: int, atom: str | int, at: int,
            depth: int = 6) -> WhyNode:
    """Why `atom` (text or id) had its bound at the end of timestep `at` in `episode`."""
    return explain_in(*episode_at(con, episode, at), atom, at, depth)


def explain_in(model: RunModel, trace: EpisodeTrace, atom: str | int, at: int, depth: int = 6) -> WhyNode:
    """`explain` on a model and an episode trace already loaded (a trace holding at least the rows up to
    `at`), for callers that explain many atoms of one episode (the replay viewer)."""
    aid = model.parse_atom(atom) if isinstance(atom, str) else int(atom)
    return _Explainer(model, trace).node(aid, trace.last_at_end_of(aid, at), depth)


def explain_change(con: RunConnection, episode: int, seq: int, depth: int = 6) -> WhyNode:
    """Why the change row `seq` of `episode` happened: that row's own cause and grounding, its body read
    where that rule read it. When an atom changes more than once in a step (immediate rules cascade in
    passes), this is the selected change's derivation, not the bound at the end of the step (`explain`)."""
    found = con.execute("SELECT t FROM raw.changes WHERE episode = $e AND seq = $s",
                        {"e": episode, "s": seq}).fetchone()
    if found is None:
        raise KeyError(f"episode {episode} has no change row with seq {seq}")
    return explain_change_in(RunModel(con), EpisodeTrace(con, episode, upto_t=int(found[0])), seq, depth)


def explain_change_in(model: RunModel, trace: EpisodeTrace, seq: int, depth: int = 6) -> WhyNode:
    """`explain_change` on a model and an episode trace already loaded that hold the row `seq`."""
    index = trace.index_of_seq(seq)
    if index is None:
        raise KeyError(f"episode {trace.episode} has no change row with seq {seq} in the rows read")
    row = trace.row(index)
    return _Explainer(model, trace).node(row.atom, row, depth)


def render_why(node: WhyNode, at: int | None = None, grid: Grid | None = None) -> str:
    """The proof tree as indented text; with the run's grid (coordinates.run_grid), cells as `30@(6,3)`."""
    lines: list[str] = []
    place = (lambda text: text) if grid is None else grid.with_coordinates

    def describe(n: WhyNode) -> str:
        c = n.cause
        if c is None or c.kind == "default":
            return "never set (the default [0,1]" + (", read as [0,0]: %closed)" if n.clause_closed else ")")
        s = f"set at t={n.t} pass {n.pass_no} {_bound_text(n.old)}->{_bound_text(n.value)} by {c.name}"
        if c.kind in ("rule", "policy"):
            delay = "!" if c.immediate else f"Δt={c.delay}"
            binds = ", ".join(f"{k}={place(v)}" for k, v in c.bindings.items())
            s += f" ({delay}{'; ' + binds if binds else ''}; {c.reads})"
        elif c.kind == "fact" and c.text:
            s += f" ({c.text})"
        if n.repeated:
            s += "  [explained above]"
        if n.truncated:
            s += "  [depth limit]"
        return s

    def walk(n: WhyNode, prefix: str, last: bool, root: bool) -> None:
        if root:
            when = f" at the end of t={at}" if at is not None else ""
            lines.append(f"{place(n.atom)} = {_bound_text(n.value)}{when}: {describe(n)}")
            child_prefix = ""
        else:
            mark = "ok " if n.holds else "NO "
            lines.append(f"{prefix}{'└─ ' if last else '├─ '}{mark}{place(n.clause)} = "
                         f"{_bound_text(n.value)}: {describe(n)}")
            child_prefix = prefix + ("   " if last else "│  ")
        for i, ch in enumerate(n.children):
            walk(ch, child_prefix, i == len(n.children) - 1, False)

    walk(node, "", True, True)
    return "\n".join(lines)


# ---- why-not ---------------------------------------------------------------------------------------------

class ClauseCheck(NamedTuple):
    pos: int                       # index of the clause in the rule body
    clause: str                    # the clause with the bindings known when it was checked
    atom: str | None               # the ground atom checked (None: no atom matched an open pattern)
    value: list[float] | None
    holds: bool
    set_at: int | None = None      # t of the change that gave `value` (None: never set)
    set_by: str | None = None
    note: str = ""
    closed: bool = False           # the clause is on a %closed predicate: [0,1] reads as [0,0]


class WhyNot:
    def __init__(self, rule: str, rule_text: str, bindings: dict[str, str], at: int, reads_at: int,
                 checks: list[ClauseCheck], failed: int | None) -> None:
        self.rule = rule
        self.rule_text = rule_text
        self.bindings = bindings                # as given, extended by the search along the checks shown
        self.at = at                            # when the head would change
        self.reads_at = reads_at                # end of this timestep is when the body is read
        self.checks = checks
        self.failed = failed                    # index into checks of the first failed clause; None if all hold
        self.head: str | None = None
        self.head_value: list[float] | None = None
        self.head_note = ""                     # why the head atom is not named (a head function the run cannot call)

    def to_dict(self) -> dict[str, Any]:
        return {**vars(self), "bindings": dict(self.bindings), "checks": [c._asdict() for c in self.checks]}


def why_not(con: RunConnection, episode: int, rule_name: str, bindings: dict[str, str],
            at: int, max_candidates: int = 100_000) -> WhyNot:
    """Which body clause of `rule_name` under `bindings` failed for a head change at `at`."""
    model = RunModel(con)
    rule = model.rule(rule_name)
    unknown = set(bindings) - set(rule.variables)
    if unknown:
        raise KeyError(f"rule {rule.name} has no variable(s) {sorted(unknown)}; its variables: "
                       f"{', '.join(rule.variables) or 'none'}")
    for value in bindings.values():
        model.node_id(value)
    reads_at = at - rule.delay
    trace = EpisodeTrace(con, episode, upto_t=reads_at)
    _check_episode(con, episode, trace)
    search = _Search(model, trace, rule, reads_at, max_candidates)
    checks, ok, binding = search.run(dict(bindings))
    result = WhyNot(rule.name, rule.text, binding, at, reads_at, checks, None if ok else len(checks) - 1)
    if ok and set(rule.head.variables()) <= set(binding):
        calls = _head_calls(model, rule.head)
        if calls:  # computed while grounding by a Python function: the run knows the head from its changes
            aid = _changed_head(con, model, rule, binding, episode)
            if aid is None:
                result.head_note = (f"its head calls the head function {calls[0]}, which the run does not "
                                    "store, and no grounding with these head values changed an atom in the "
                                    "episode: its head atom is unknown")
                return result
            result.head = model.atom_texts([aid])[aid]
        else:
            args = tuple(binding.get(a, a) if v else a for a, v in zip(rule.head.args, rule.head.is_var))
            aid = model.find_atom(rule.head.label, args)
            result.head = f"{rule.head.label}({','.join(args)})"
        head_row = None if aid is None else EpisodeTrace(con, episode, upto_t=at).last_at_end_of(aid, at)
        result.head_value = list(EpisodeTrace.bound(head_row))
    return result


# a head argument that calls a head function is stored as the call's text, `f(X)` (engine/program.py Term)
_CALL_RE = re.compile(r"[a-z][A-Za-z0-9_]*\(.*\)", re.S)
_CALL_ARG_RE = re.compile(r"\"[^\"]*\"|'[^']*'|[^,\s]+")  # a call's arguments: quoted constants, names
_CAUSE_RULE = next(code for code, name in CAUSE_NAMES.items() if name == "rule")


def _head_calls(model: RunModel, head: Clause) -> list[str]:
    """The head's arguments that call a head function (a node of that name is a node, not a call)."""
    return [a for a, v in zip(head.args, head.is_var)
            if not v and a not in model.node_ids and _CALL_RE.fullmatch(a)]


def _changed_head(con: RunConnection, model: RunModel, rule: RuleInfo, binding: dict[str, str],
                  episode: int) -> int | None:
    """The head atom of `rule` under `binding`, read off the changes of the episode: the atom changed by a
    grounding of the rule that agrees with `binding` on the variables the head reads (its arguments' and
    its calls'), which all name the same head. None when none changed an atom (or one is unbound)."""
    head_vars = set(rule.head.variables())
    for call in _head_calls(model, rule.head):
        head_vars.update(t for t in _CALL_ARG_RE.findall(call[call.index("(") + 1:-1]) if t in rule.variables)
    if not head_vars <= set(binding):
        return None
    where = "".join(f" AND g.var_values[{rule.variables.index(v) + 1}] = ?" for v in sorted(head_vars))
    params = [rule.rule, episode, _CAUSE_RULE] + [model.node_ids[binding[v]] for v in sorted(head_vars)]
    rows = con.execute("SELECT c.atom FROM raw.groundings g JOIN raw.changes c ON c.grounding = g.grounding "
                       "WHERE g.rule = ? AND c.episode = ? AND c.cause_kind = ?" + where + " LIMIT 1",
                       params).fetchall()
    return int(rows[0][0]) if rows else None


class _Search:
    """Depth-first search over the rule body, in body order (clauses that cannot bind their unbound
    variables wait until a later clause binds them); keeps the path that got furthest."""

    def __init__(self, model: RunModel, trace: EpisodeTrace, rule: RuleInfo, reads_at: int,
                 budget: int) -> None:
        self.m, self.tr, self.rule, self.at, self.budget = model, trace, rule, reads_at, budget
        self.best: list[ClauseCheck] = []
        self.best_binding: dict[str, str] = {}

    def _check(self, pos: int, clause: Clause, aid: int | None, atom: str, binding: dict[str, str]
               ) -> ClauseCheck:
        row = None if aid is None else self.tr.last_at_end_of(aid, self.at)
        value = EpisodeTrace.bound(row)
        return ClauseCheck(pos, clause.ground_text(binding), atom, list(value), satisfies(value, clause),
                           set_at=None if row is None else row.t,
                           set_by=None if row is None else set_by(self.m, row),
                           closed=clause.closed)

    def run(self, binding: dict[str, str]) -> tuple[list[ClauseCheck], bool, dict[str, str]]:
        found = self._dfs(list(range(len(self.rule.body))), binding, [])
        if found is not None:
            return found[0], True, found[1]
        return self.best, False, self.best_binding

    def _record(self, path: list[ClauseCheck], binding: dict[str, str]) -> None:
        if len(path) > len(self.best):
            self.best, self.best_binding = path, dict(binding)

    def _dfs(self, todo: list[int], binding: dict[str, str], path: list[ClauseCheck]
             ) -> tuple[list[ClauseCheck], dict[str, str]] | None:
        if not todo:
            return path, binding
        # the first clause in body order that is ground, or that can bind its open variables
        for k, pos in enumerate(todo):
            clause = self.rule.body[pos]
            open_vars = [v for v in clause.variables() if v not in binding]
            if not open_vars or clause.binds:
                break
        else:
            k, pos = 0, todo[0]
            clause = self.rule.body[pos]
            open_vars = [v for v in clause.variables() if v not in binding]
        rest = todo[:k] + todo[k + 1:]
        args = tuple(binding.get(a) if v else a for a, v in zip(clause.args, clause.is_var))
        if not open_vars:
            aid = self.m.find_atom(clause.label, args)  # type: ignore[arg-type]
            check = self._check(pos, clause, aid, f"{clause.label}({','.join(args)})", binding)  # type: ignore[arg-type]
            if not check.holds:
                self._record(path + [check], binding)
                return None
            return self._dfs(rest, binding, path + [check])
        candidates = self.m.atoms_matching(clause.label, args)
        tried = 0
        for aid, cargs in candidates:
            new = dict(binding)
            clash = False
            for a, is_var, value in zip(clause.args, clause.is_var, cargs):
                if is_var:
                    if new.setdefault(a, value) != value:
                        clash = True
            if clash:
                continue
            self.budget -= 1
            if self.budget < 0:
                raise RuntimeError("why-not search budget exhausted; give more variable bindings")
            check = self._check(pos, clause, aid, f"{clause.label}({','.join(cargs)})", new)
            if check.holds:
                tried += 1
                found = self._dfs(rest, new, path + [check])
                if found is not None:
                    return found
        if tried == 0:
            pattern = clause.ground_text(binding)
            self._record(path + [ClauseCheck(
                pos, pattern, None, None, False,
                note=f"no atom matching {pattern} holds at the end of t={self.at} "
                     f"({len(candidates)} candidate(s) in the vocabulary)")], binding)
        return None


def render_why_not(w: WhyNot) -> str:
    lines = [f"rule {w.rule}: {w.rule_text.removeprefix(w.rule + ':').strip()}",
             f"bindings: {', '.join(f'{k}={v}' for k, v in w.bindings.items()) or 'none'}; "
             f"body read at the end of t={w.reads_at} (head at t={w.at})"]
    for i, c in enumerate(w.checks):
        mark = "ok " if c.holds else "NO "
        if c.atom is None:
            lines.append(f"  {mark}{c.clause}: {c.note}")
            continue
        src = f"set at t={c.set_at} by {c.set_by}" if c.set_at is not None else (
            "never set, read as [0,0]: %closed" if c.closed else "never set")
        lines.append(f"  {mark}{c.clause}: {c.atom} = {_bound_text(c.value)} ({src})")
    if w.failed is None:
        lines.append("every body clause holds: the rule was active"
                     + (f"; its head {w.head} = {_bound_text(w.head_value)} at the end of t={w.at}"
                        if w.head else f"; {w.head_note}" if w.head_note else ""))
    else:
        c = w.checks[w.failed]
        lines.append(f"first failed clause: #{c.pos + 1} {c.clause}"
                     + (f" ({c.atom} = {_bound_text(c.value)})" if c.atom else ""))
    return "\n".join(lines)
