"""Row sources the lazy table pages from: `prepare()` (in a worker) returns the row count, `fetch(page)`
returns one page of PAGE rows as dicts. Nothing fetches more than the pages asked for.

- ArrowSource: rows already in memory (the run catalog, SQL console results).
- QuerySource: any read-only SELECT, paged with LIMIT/OFFSET under a total order (small tables: episodes,
  rules).
- TraceSource: an episode's change rows under filters, paged by keyset on seq: prepare() counts them and
  page 0 is a top-N query, so the first screen comes at once; warm() (run by the table when idle) takes
  every PAGE-th seq of the filtered rows (the anchors), so page k is `seq >= anchors[k] AND seq <
  anchors[k+1]`, which the sealed file's (episode, seq) order and Parquet row-group statistics answer
  without a scan."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import pyarrow as pa

from tracelab.store.reader import query_readonly
from tracelab.viewers.tui.source import RunSource

PAGE = 256


class PageSource(Protocol):
    def prepare(self) -> int: ...     # may set `start_row`: where the cursor opens
    def fetch(self, page: int) -> list[dict[str, Any]]: ...
    def warm(self) -> None: ...        # optional work done when the table has fetched what it showed


def fetch_span(source: PageSource, first: int, last: int) -> list[tuple[int, list[dict[str, Any]]]]:
    """Pages first..last of any source (in one query where the source can)."""
    many = getattr(source, "fetch_pages", None)
    if many is not None:
        return many(first, last)
    return [(p, source.fetch(p)) for p in range(first, last + 1)]


class ArrowSource:
    def __init__(self, table: pa.Table) -> None:
        self.table = table

    def prepare(self) -> int:
        return self.table.num_rows

    def warm(self) -> None:
        pass

    def fetch(self, page: int) -> list[dict[str, Any]]:
        return self.table.slice(page * PAGE, PAGE).to_pylist()


class QuerySource:
    """`sql` (one SELECT) ordered by `order` (tie-broken by the caller: every ORDER BY is total)."""

    def __init__(self, source: RunSource, sql: str, order: str, params: dict[str, Any] | None = None
                 ) -> None:
        self.source, self.sql, self.order, self.params = source, sql, order, params

    def prepare(self) -> int:
        return int(self.source.scalar(f"SELECT count(*) FROM ({self.sql})", self.params))

    def warm(self) -> None:
        pass

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
    def build(cls, source: RunSource, f: TraceFilter) -> "TraceQuery":
        """The clause, with `{atom}` where the atom id column goes (on() puts it in)."""
        atom_col = "{atom}"
        where, params = ["episode = $episode"], {"episode": f.episode}
        if f.t_from is not None:
            where.append("t >= $t_from")
            params["t_from"] = f.t_from
        if f.t_to is not None:
            where.append("t <= $t_to")
            params["t_to"] = f.t_to
        if f.atom:
            where.append(cls._atom_clause(source, atom_col, "text", f.atom))
        if f.label:
            where.append(cls._atom_clause(source, atom_col, "label", f.label))
        if f.atom_id is not None:
            where.append(f"{atom_col} = $atom_id")
            params["atom_id"] = f.atom_id
        if f.rule:
            where.append(cls._cause_clause(source, f.rule))
        return cls(" AND ".join(where), params)

    def on(self, atom_col: str) -> "TraceQuery":
        """The clause over a table whose atom id column is `atom_col` (raw.changes: atom; the changes
        view: atom_id)."""
        return TraceQuery(self.where.replace("{atom}", atom_col), self.params)

    @staticmethod
    def _atom_clause(source: RunSource, atom_col: str, column: str, pattern: str) -> str:
        """`atom IN (ids)` for the atoms whose text (or label) matches the glob: resolved once against
        the small atoms view, so the scans of millions of change rows test integers."""
        ids = [r["atom"] for r in source.rows(f"SELECT atom FROM atoms WHERE {column} GLOB $p ORDER BY atom",
                                              {"p": pattern})]
        return f"{atom_col} IN ({', '.join(map(str, ids))})" if ids else "FALSE"

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
    """One episode's change rows under a TraceFilter, in seq order, paged by keyset (module doc).

    A page is found from a *hint* when one is near: (row r, seq bound b) means "row r is the first filtered
    row with seq >= b". Jumps leave one (row_of_t, row_of_seq, next_change), every fetched page leaves one
    at each of its edges, and row 0 and row `count` are known; a page within reach of a hint costs two
    top-N scans of the seq column (~10 ms at 10M rows). Anything else uses the anchors (warm())."""

    def __init__(self, source: RunSource, flt: TraceFilter, start: tuple[str, int] | None = None) -> None:
        """start: ("seq", s) or ("t", t): open at the first filtered row with seq >= s (or t >= t)."""
        if start is not None and start[0] not in ("seq", "t"):
            raise ValueError(f"start must be on seq or t, not {start[0]!r}")
        self.source, self.filter, self.start = source, flt, start
        self.anchors: np.ndarray | None = None    # seq of every PAGE-th filtered row (warm() makes it)
        self.count = 0
        self.start_row = 0                         # where the table's cursor opens
        self.hints: dict[int, int] = {}
        self._raw: TraceQuery | None = None
        self._view: TraceQuery | None = None

    def prepare(self) -> int:
        """The filtered row count (the table shows pages near a hint before the anchors exist)."""
        query = TraceQuery.build(self.source, self.filter)
        self._raw, self._view = query.on("atom"), query.on("atom_id")
        params, before, at = dict(self._raw.params), "FALSE", "FALSE"
        if self.start is not None:   # t never decreases with seq within an episode: one scan finds both
            column, params["start"] = self.start
            before, at = f"{column} < $start", f"{column} >= $start"
        # one scan: the count, the ends, and where the start is (its row and its seq)
        row = self.source.rows(f"SELECT count(*) AS n, min(seq) AS first, max(seq) AS last, "
                               f"count(*) FILTER ({before}) AS at_row, min(seq) FILTER ({at}) AS at_seq "
                               f"FROM raw.changes WHERE {self._raw.where}", params)[0]
        self.count = int(row["n"])
        if self.count:
            self.hints = {0: int(row["first"]), self.count: int(row["last"]) + 1}
        if row["at_seq"] is not None:
            self.start_row = int(row["at_row"])
            self.hints[self.start_row] = int(row["at_seq"])
        elif self.start is not None and self.count:
            self.start_row = self.count - 1
        return self.count

    def count_now(self) -> int:
        """The filtered row count now (a live run grows; `count` is as of prepare())."""
        assert self._raw is not None
        return int(self.source.scalar(f"SELECT count(*) FROM raw.changes WHERE {self._raw.where}",
                                      self._raw.params))

    def warm(self) -> None:
        """Compute the anchors: the filtered seqs in scan order (a sealed run stores them sorted; sorted
        here only if not), every PAGE-th kept. ~0.3 s for 10M rows, against ~1.5 s for a window query."""
        if self.anchors is not None or self._raw is None:
            return
        raw = self._raw
        seqs = self.source.call(lambda con: query_readonly(
            con, f"SELECT seq FROM raw.changes WHERE {raw.where}", raw.params).fetchnumpy()["seq"])
        seqs = np.asarray(seqs, dtype=np.int64)
        if len(seqs) > 1 and not bool(np.all(seqs[1:] > seqs[:-1])):
            seqs = np.sort(seqs)
        self.anchors = seqs[::PAGE].copy()

    def fetch(self, page: int) -> list[dict[str, Any]]:
        return self.fetch_pages(page, page)[0][1]

    def fetch_pages(self, first: int, last: int) -> list[tuple[int, list[dict[str, Any]]]]:
        """Pages first..last; near a hint, all of them with one range query."""
        assert self._raw is not None, "prepare() first"
        last = min(last, max(0, (self.count - 1) // PAGE))
        if self.anchors is not None:
            spans = []
            for page in range(first, last + 1):
                hi = int(self.anchors[page + 1]) if page + 1 < len(self.anchors) else None
                spans.append((page, self._rows(int(self.anchors[page]), hi) if page < len(self.anchors) else []))
            return spans
        near = [r for r in self.hints if first * PAGE <= r <= (last + 1) * PAGE]
        if not near:
            self.warm()
            return self.fetch_pages(first, last)
        r = min(near, key=lambda r: abs(r - first * PAGE))
        rows = self._rows(*self._range_around(first, last, r, self.hints[r]))
        spans = [(p, rows[(p - first) * PAGE:(p - first + 1) * PAGE]) for p in range(first, last + 1)]
        for page, part in spans:
            if part:
                self.hints.setdefault(page * PAGE, int(part[0]["seq"]))
                self.hints.setdefault(page * PAGE + len(part), int(part[-1]["seq"]) + 1)
        return spans

    def _range_around(self, first: int, last: int, row: int, bound: int) -> tuple[int, int]:
        """[lo, hi) in seq of pages first..last, given that `row` is the first filtered row with
        seq >= bound."""
        assert self._raw is not None
        where, params = self._raw.where, {**self._raw.params, "b": bound}
        before = row - first * PAGE                # rows of the span before the hinted one
        after = min((last + 1) * PAGE, self.count) - row
        lo = bound if before == 0 else self.source.scalar(
            f"SELECT min(seq) FROM (SELECT seq FROM raw.changes WHERE {where} AND seq < $b "
            f"ORDER BY seq DESC LIMIT {before})", params)
        hi = bound if after <= 0 else int(self.source.scalar(
            f"SELECT max(seq) FROM (SELECT seq FROM raw.changes WHERE {where} AND seq >= $b "
            f"ORDER BY seq LIMIT {after})", params)) + 1
        return int(lo), hi

    def _rows(self, lo: int, hi: int | None) -> list[dict[str, Any]]:
        """The filtered rows with lo <= seq < hi, read from the changes view (joins only these rows)."""
        assert self._view is not None
        params = {**self._view.params, "lo": lo}
        upper = ""
        if hi is not None:
            params["hi"] = hi
            upper = " AND seq < $hi"
        return self.source.rows(f"SELECT {TRACE_COLUMNS} FROM changes WHERE {self._view.where} "
                                f"AND seq >= $lo{upper} ORDER BY seq", params)

    def _locate(self, condition: str, params: dict[str, Any]) -> int | None:
        """The row index of the first filtered row meeting `condition` (on raw.changes), noted as a hint;
        None if no row meets it."""
        assert self._raw is not None
        where, params = self._raw.where, {**self._raw.params, **params}
        first = self.source.scalar(f"SELECT min(seq) FROM raw.changes WHERE {where} AND {condition}", params)
        if first is None:
            return None
        row = int(self.source.scalar(f"SELECT count(*) FROM raw.changes WHERE {where} AND seq < $first",
                                     {**self._raw.params, "first": first}))
        self.hints[row] = int(first)
        return row

    def row_of_seq(self, seq: int) -> int:
        """The row index of the first filtered row with seq >= `seq` (the last row if there is none)."""
        found = self._locate("seq >= $s", {"s": seq})
        return max(0, self.count - 1) if found is None else found

    def row_of_t(self, t: int) -> int:
        """The row index of the first filtered row at or after timestep t (the last row if none)."""
        found = self._locate("t >= $tt", {"tt": t})
        return max(0, self.count - 1) if found is None else found

    def next_change(self, atom_id: int, seq: int, forward: bool) -> int | None:
        """The row index of the atom's next (or previous) change after (before) `seq`, if any."""
        assert self._raw is not None
        agg, cmp = ("min", ">") if forward else ("max", "<")
        found = self.source.scalar(f"SELECT {agg}(seq) FROM raw.changes WHERE {self._raw.where} "
                                   f"AND atom = $a AND seq {cmp} $s", {**self._raw.params, "a": atom_id, "s": seq})
        return None if found is None else self.row_of_seq(int(found))
