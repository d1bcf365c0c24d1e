"""Row sources the lazy table pages from: `prepare()` (in a worker) returns the row count, `fetch(page)`
returns one page of PAGE rows as dicts. Nothing fetches more than the pages asked for.

- ArrowSource: rows already in memory (the run catalog, SQL console results).
- QuerySource: any read-only SELECT, paged with LIMIT/OFFSET under a total order (small tables: episodes,
  rules).
- TraceSource: an episode's change rows under filters, paged by keyset on seq: prepare() takes every
  PAGE-th seq of the filtered rows (the anchors), so page k is `seq >= anchors[k] AND seq < anchors[k+1]`,
  which the sealed file's (episode, seq) order and Parquet row-group statistics answer without a scan."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import pyarrow as pa

from tracelab.viewers.tui.source import RunSource

PAGE = 256


class PageSource(Protocol):
    def prepare(self) -> int: ...
    def fetch(self, page: int) -> list[dict[str, Any]]: ...


class ArrowSource:
    def __init__(self, table: pa.Table) -> None:
        self.table = table

    def prepare(self) -> int:
        return self.table.num_rows

    def fetch(self, page: int) -> list[dict[str, Any]]:
        return self.table.slice(page * PAGE, PAGE).to_pylist()


class QuerySource:
    """`sql` (one SELECT) ordered by `order` (tie-broken by the caller: every ORDER BY is total)."""

    def __init__(self, source: RunSource, sql: str, order: str, params: dict[str, Any] | None = None
                 ) -> None:
        self.source, self.sql, self.order, self.params = source, sql, order, params

    def prepare(self) -> int:
        return int(self.source.scalar(f"SELECT count(*) FROM ({self.sql})", self.params))

    def fetch(self, page: int) -> list[dict[str, Any]]:
        return self.source.rows(f"SELECT * FROM ({self.sql}) ORDER BY {self.order} "
                                f"LIMIT {PAGE} OFFSET {page * PAGE}", self.params)


@dataclass
class TraceFilter:
    """What the trace shows: one episode, a time range, and GLOB patterns on atom text, label and rule
    name (rule also matches fact:NAME, action, policy:NAME, reset, as the changes view names them)."""
    episode: int
    t_from: int | None = None
    t_to: int | None = None
    atom: str = ""
    label: str = ""
    rule: str = ""
    atom_id: int | None = None          # one atom (by id), e.g. from the board or the why tree

    def describe(self) -> str:
        parts = [f"episode {self.episode}"]
        if self.t_from is not None or self.t_to is not None:
            parts.append(f"t {'' if self.t_from is None else self.t_from}..{'' if self.t_to is None else self.t_to}")
        parts += [f"{k} {v}" for k, v in (("atom", self.atom), ("label", self.label), ("rule", self.rule)) if v]
        if self.atom_id is not None:
            parts.append(f"atom #{self.atom_id}")
        return ", ".join(parts)


# The names the changes view gives causes, as (cause_kind, cause_id, name) rows; id -1: any id.
_CAUSES_SQL = """
SELECT 2 AS kind, rule AS id, name FROM raw.rules
UNION ALL SELECT 0, fact, 'fact:' || name FROM raw.facts
UNION ALL SELECT 3, code, 'policy:' || name FROM raw.policies
UNION ALL SELECT 1, -1, 'action'
UNION ALL SELECT 4, -1, 'reset'
"""


@dataclass
class TraceQuery:
    """The WHERE clause of a TraceFilter over raw.changes columns (atom and cause ids), with its named
    parameters; rule globs are resolved to cause ids once, against the small rules/facts tables."""
    where: str
    params: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def build(cls, source: RunSource, f: TraceFilter, atom_col: str = "atom") -> "TraceQuery":
        where, params = ["episode = $episode"], {"episode": f.episode}
        if f.t_from is not None:
            where.append("t >= $t_from")
            params["t_from"] = f.t_from
        if f.t_to is not None:
            where.append("t <= $t_to")
            params["t_to"] = f.t_to
        if f.atom:
            where.append(f"{atom_col} IN (SELECT atom FROM atoms WHERE text GLOB $atom)")
            params["atom"] = f.atom
        if f.label:
            where.append(f"{atom_col} IN (SELECT atom FROM atoms WHERE label GLOB $label)")
            params["label"] = f.label
        if f.atom_id is not None:
            where.append(f"{atom_col} = $atom_id")
            params["atom_id"] = f.atom_id
        if f.rule:
            where.append(cls._cause_clause(source, f.rule))
        return cls(" AND ".join(where), params)

    @staticmethod
    def _cause_clause(source: RunSource, pattern: str) -> str:
        by_kind: dict[int, list[int]] = {}
        for r in source.rows(f"SELECT kind, id FROM ({_CAUSES_SQL}) WHERE name GLOB $p ORDER BY kind, id",
                             {"p": pattern}):
            by_kind.setdefault(r["kind"], []).append(r["id"])
        terms = []
        for kind, ids in by_kind.items():
            if -1 in ids:
                terms.append(f"cause_kind = {kind}")
            else:
                terms.append(f"(cause_kind = {kind} AND cause_id IN ({', '.join(map(str, ids))}))")
        return "(" + (" OR ".join(terms) or "FALSE") + ")"


TRACE_COLUMNS = ("t, pass_no, atom, node, label, old_lower, old_upper, new_lower, new_upper, rule, "
                 "seq, atom_id, grounding, cause_kind")


class TraceSource:
    """One episode's change rows under a TraceFilter, in seq order, paged by keyset (module doc)."""

    def __init__(self, source: RunSource, flt: TraceFilter) -> None:
        self.source, self.filter = source, flt
        self.anchors = np.zeros(0, np.int64)
        self.count = 0
        self._raw: TraceQuery | None = None
        self._view: TraceQuery | None = None

    def prepare(self) -> int:
        self._raw = TraceQuery.build(self.source, self.filter)
        self._view = TraceQuery.build(self.source, self.filter, atom_col="atom_id")  # the view's names
        table = self.source.arrow(
            f"SELECT seq, count(*) OVER () AS n FROM (SELECT seq, row_number() OVER (ORDER BY seq) - 1 AS i "
            f"FROM raw.changes WHERE {self._raw.where}) WHERE i % {PAGE} = 0 ORDER BY seq",
            self._raw.params)
        self.anchors = table.column("seq").to_numpy()
        if len(self.anchors) == 0:
            self.count = 0
        else:
            last_start = int(self.anchors[-1])
            tail = self.source.scalar(f"SELECT count(*) FROM raw.changes WHERE {self._raw.where} "
                                      f"AND seq >= $lo", {**self._raw.params, "lo": last_start})
            self.count = (len(self.anchors) - 1) * PAGE + int(tail)
        return self.count

    def fetch(self, page: int) -> list[dict[str, Any]]:
        assert self._view is not None, "prepare() first"
        if page >= len(self.anchors):
            return []
        params = {**self._view.params, "lo": int(self.anchors[page])}
        upper = ""
        if page + 1 < len(self.anchors):
            params["hi"] = int(self.anchors[page + 1])
            upper = " AND seq < $hi"
        return self.source.rows(f"SELECT {TRACE_COLUMNS} FROM changes WHERE {self._view.where} "
                                f"AND seq >= $lo{upper} ORDER BY seq", params)

    def row_of_seq(self, seq: int) -> int:
        """The row index of the first filtered row with seq >= `seq`."""
        assert self._raw is not None
        return int(self.source.scalar(f"SELECT count(*) FROM raw.changes WHERE {self._raw.where} "
                                      f"AND seq < $s", {**self._raw.params, "s": seq}))

    def row_of_t(self, t: int) -> int:
        """The row index of the first filtered row at or after timestep t."""
        assert self._raw is not None
        return int(self.source.scalar(f"SELECT count(*) FROM raw.changes WHERE {self._raw.where} "
                                      f"AND t < $tt", {**self._raw.params, "tt": t}))

    def next_change(self, atom_id: int, seq: int, forward: bool) -> int | None:
        """The row index of the atom's next (or previous) change after (before) `seq`, if any."""
        assert self._raw is not None
        agg, cmp = ("min", ">") if forward else ("max", "<")
        found = self.source.scalar(f"SELECT {agg}(seq) FROM raw.changes WHERE {self._raw.where} "
                                   f"AND atom = $a AND seq {cmp} $s",
                                   {**self._raw.params, "a": atom_id, "s": seq})
        return None if found is None else self.row_of_seq(int(found))
