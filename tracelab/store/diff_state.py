"""What two episodes were given and where they ended, for `tracelab diff` (tracelab.store.diff): the
question a reasoning's user asks after changing a fact or a rule is "what changed because of it?".

- given: the rules and the facts of each episode (a fact given for one episode only, `facts.episode`,
  belongs to that one), compared by content, not by id or name: a rule by its text, a fact by its
  literal, window and static flag. A fact or rule only on one side whose atom (or rule name) is on the
  other side too is reported as changed.
- ended: each atom's bound at the end of each episode (its last change; never set: [0,1]), compared by
  the atom's text; the atoms whose bounds differ.

Each side is read through its run's own connection; the comparison runs in the caller's scratch
in-memory database (diff._scratch), which reaches no file."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import duckdb

from tracelab.store.reader import RunConnection

SHOWN_ROWS = 1000  # differing facts, rules or atoms listed (the counts cover all of them)

_FACTS_SQL = """
SELECT literal, split_part(literal, ':[', 1) AS atom, start, "end", static, name
FROM raw.facts WHERE episode IS NULL OR episode = $e
"""
_RULES_SQL = "SELECT name, regexp_replace(text, '\\s+', ' ', 'g') AS text FROM raw.rules"
_FINAL_SQL = """
SELECT atom, arg_max(new_lower, seq) AS lower, arg_max(new_upper, seq) AS upper
FROM changes WHERE episode = $e GROUP BY atom
"""

# rows of one side not matched on the other (as multisets: a fact given twice counts twice)
_UNMATCHED_FACTS_SQL = """
WITH a AS (SELECT *, row_number() OVER (PARTITION BY literal, start, "end", static ORDER BY name) AS k
           FROM facts_a),
     b AS (SELECT *, row_number() OVER (PARTITION BY literal, start, "end", static ORDER BY name) AS k
           FROM facts_b)
SELECT 'a' AS side, a.atom, a.literal, a.start, a."end", a.static, a.name FROM a
  ANTI JOIN b USING (literal, start, "end", static, k)
UNION ALL
SELECT 'b', b.atom, b.literal, b.start, b."end", b.static, b.name FROM b
  ANTI JOIN a USING (literal, start, "end", static, k)
ORDER BY atom, side, start
"""
_UNMATCHED_RULES_SQL = """
SELECT 'a' AS side, name, text FROM rules_a ANTI JOIN rules_b USING (text)
UNION ALL SELECT 'b', name, text FROM rules_b ANTI JOIN rules_a USING (text)
ORDER BY name, side
"""
_FINAL_DIFF_SQL = """
SELECT coalesce(a.atom, b.atom) AS atom, coalesce(a.lower, 0.0) AS lower_a, coalesce(a.upper, 1.0) AS upper_a,
       coalesce(b.lower, 0.0) AS lower_b, coalesce(b.upper, 1.0) AS upper_b
FROM final_a a FULL JOIN final_b b USING (atom)
WHERE coalesce(a.lower, 0.0) <> coalesce(b.lower, 0.0) OR coalesce(a.upper, 1.0) <> coalesce(b.upper, 1.0)
ORDER BY atom
"""


@dataclass
class GivenDifference:
    """Facts and rules given to one side and not to the other (`changed`: the same atom or rule name on
    both sides, with another bound, window or text)."""
    facts_only_in_a: list[dict[str, Any]] = field(default_factory=list)
    facts_only_in_b: list[dict[str, Any]] = field(default_factory=list)
    facts_changed: list[dict[str, Any]] = field(default_factory=list)
    rules_only_in_a: list[dict[str, Any]] = field(default_factory=list)
    rules_only_in_b: list[dict[str, Any]] = field(default_factory=list)
    rules_changed: list[dict[str, Any]] = field(default_factory=list)

    @property
    def same(self) -> bool:
        return not any(asdict(self).values())

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class EndDifference:
    """The atoms whose bounds differ at the end of the two episodes (`atoms` lists the first
    SHOWN_ROWS by atom text; `count` is all of them)."""
    count: int = 0
    atoms: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _register(scratch: duckdb.DuckDBPyConnection, name: str, con: RunConnection, sql: str, episode: int) -> None:
    params = {"e": episode} if "$e" in sql else None
    scratch.register(name, con.sql(sql, params=params).to_arrow_table())


def _dicts(cur: duckdb.DuckDBPyConnection) -> list[dict[str, Any]]:
    names = [d[0] for d in cur.description]
    return [dict(zip(names, r)) for r in cur.fetchall()]


def given_difference(scratch: duckdb.DuckDBPyConnection, con_a: RunConnection, a: int,
                     con_b: RunConnection, b: int) -> GivenDifference:
    """The facts and rules episode `a` (of con_a's run) and episode `b` (of con_b's) were given that
    the other was not."""
    _register(scratch, "facts_a", con_a, _FACTS_SQL, a)
    _register(scratch, "facts_b", con_b, _FACTS_SQL, b)
    _register(scratch, "rules_a", con_a, _RULES_SQL, a)
    _register(scratch, "rules_b", con_b, _RULES_SQL, b)
    d = GivenDifference()
    facts = _dicts(scratch.execute(_UNMATCHED_FACTS_SQL))
    rules = _dicts(scratch.execute(_UNMATCHED_RULES_SQL))
    _split(facts, "atom", d.facts_only_in_a, d.facts_only_in_b, d.facts_changed)
    _split(rules, "name", d.rules_only_in_a, d.rules_only_in_b, d.rules_changed)
    return d


def _split(rows: list[dict[str, Any]], key: str, only_a: list[dict[str, Any]], only_b: list[dict[str, Any]],
           changed: list[dict[str, Any]]) -> None:
    """Unmatched rows into: changed (the key on both sides: one entry with a and b), only in a, only in b
    (at most SHOWN_ROWS each)."""
    keys_a = {r[key] for r in rows if r["side"] == "a"}
    keys_b = {r[key] for r in rows if r["side"] == "b"}
    both = keys_a & keys_b
    pairs: dict[Any, dict[str, Any]] = {}
    for r in rows:
        side = r.pop("side")
        if r[key] in both:
            pairs.setdefault(r[key], {key: r[key], "a": [], "b": []})[side].append(r)
        else:
            target = only_a if side == "a" else only_b
            if len(target) < SHOWN_ROWS:
                target.append(r)
    changed.extend(list(pairs.values())[:SHOWN_ROWS])


def end_difference(scratch: duckdb.DuckDBPyConnection, con_a: RunConnection, a: int,
                   con_b: RunConnection, b: int) -> EndDifference:
    """The atoms whose bound at the end of episode `a` differs from the one at the end of `b`."""
    _register(scratch, "final_a", con_a, _FINAL_SQL, a)
    _register(scratch, "final_b", con_b, _FINAL_SQL, b)
    count = scratch.execute(f"SELECT count(*) FROM ({_FINAL_DIFF_SQL})").fetchall()[0][0]
    atoms = _dicts(scratch.execute(f"{_FINAL_DIFF_SQL} LIMIT {SHOWN_ROWS}"))
    return EndDifference(int(count), atoms)


def _bound(lo: float, up: float) -> str:
    return f"[{lo:g},{up:g}]"


def _fact_text(f: dict[str, Any]) -> str:
    window = f"@{f['start']}" if f["start"] == f["end"] else f"@{f['start']}..{f['end']}"
    return f"{f['literal']} {window}{' static' if f['static'] else ''}"


def render_given(d: GivenDifference, ea: str, eb: str, shown: int = 10) -> list[str]:
    """Text lines: what the two episodes were given that the other was not."""
    if d.same:
        return ["given: the same rules and facts"]
    lines = ["given:"]
    for what, changed, only_a, only_b, text in (
            ("fact", d.facts_changed, d.facts_only_in_a, d.facts_only_in_b, _fact_text),
            ("rule", d.rules_changed, d.rules_only_in_a, d.rules_only_in_b, lambda r: r["text"])):
        for c in changed[:shown]:
            lines.append(f"  {what} changed: {'; '.join(map(text, c['a']))} in {ea}, "
                         f"{'; '.join(map(text, c['b']))} in {eb}")
        for label, rows in ((f"only in {ea}", only_a), (f"only in {eb}", only_b)):
            for r in rows[:shown]:
                lines.append(f"  {what} {label}: {text(r)}")
        more = max(0, len(changed) - shown) + max(0, len(only_a) - shown) + max(0, len(only_b) - shown)
        if more:
            lines.append(f"  ... {more} more {what} difference(s) (--json lists up to {SHOWN_ROWS} of each kind)")
    return lines


def render_end(d: EndDifference, ea: str, eb: str, shown: int = 10) -> list[str]:
    """Text lines: the atoms whose bounds differ at the two episodes' ends."""
    if not d.count:
        return ["at the end: every atom has the same bound"]
    lines = [f"at the end: {d.count:,} atom{'s' if d.count != 1 else ''} with another bound"]
    for r in d.atoms[:shown]:
        lines.append(f"  {r['atom']}: {_bound(r['lower_a'], r['upper_a'])} in {ea}, "
                     f"{_bound(r['lower_b'], r['upper_b'])} in {eb}")
    if d.count > shown:
        lines.append(f"  ... {d.count - shown:,} more (--json lists the first {min(d.count, SHOWN_ROWS):,})")
    return lines
