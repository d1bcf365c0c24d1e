"""An episode's change rows for the trace's lazy table (paging.py's protocol), paged by keyset on seq:
prepare() counts them and page 0 is a top-N query, so the first screen comes at once; warm() (run by the
table when idle) takes every PAGE-th seq of the filtered rows (the anchors), so page k is `seq >=
anchors[k] AND seq < anchors[k+1]`, which the sealed file's (episode, seq) order and Parquet row-group
statistics answer without a scan. On a sealed run warm() reads the episode's index (episode_index.py)
instead, and every later filter, jump and next change of that episode is answered from it without
scanning the rows. Its own module: it loads numpy, which the first screen (the Episodes table) does not."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tracelab.store.coordinates import Grid, run_grid
from tracelab.store.reader import query_readonly
from tracelab.store.static_facts import FACT_CAUSE
from tracelab.viewers.tui.episode_index import EpisodeIndex, RowSelection, cached_index, episode_index
from tracelab.viewers.tui.paging import PAGE
from tracelab.viewers.tui.source import RunSource


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
    hide_static: bool = False           # leave out the rows of static facts (the trace pane does by default)
    atom_text: str = ""                 # the text of atom_id, for the status line (`a`: only this atom)

    def describe(self) -> str:
        parts = [f"episode {self.episode}"]
        if self.t_from is not None or self.t_to is not None:
            parts.append(f"t {'' if self.t_from is None else self.t_from}..{'' if self.t_to is None else self.t_to}")
        parts += [f"{k} {v}" for k, v in (("atom", self.atom), ("label", self.label), ("rule", self.rule)) if v]
        if self.atom_id is not None:
            parts.append(f"only {self.atom_text}" if self.atom_text else f"atom #{self.atom_id}")
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
    parameters, and the same filter as resolved ids (`selection`, for an EpisodeIndex); atom, label and
    rule globs are resolved to ids once, against the small atoms, rules and facts tables."""
    where: str
    params: dict[str, Any] = field(default_factory=dict)
    selection: RowSelection | None = None
    hidden_where: str | None = None     # the rows the filter keeps but for hiding static facts' (counted)

    @classmethod
    def build(cls, source: RunSource, f: TraceFilter) -> "TraceQuery":
        """The clause, with `{atom}` where the atom id column goes (on() puts it in)."""
        atom_col = "{atom}"
        sel = RowSelection([], None, f.t_from, f.t_to)
        where, params = ["episode = $episode"], {"episode": f.episode}
        if f.t_from is not None:
            where.append("t >= $t_from")
            params["t_from"] = f.t_from
        if f.t_to is not None:
            where.append("t <= $t_to")
            params["t_to"] = f.t_to
        for column, pattern in (("text", f.atom), ("label", f.label)):
            if pattern:
                sel.atom_sets.append(cls._atom_ids(source, column, pattern))
                where.append(cls._in(atom_col, sel.atom_sets[-1]))
        if f.atom_id is not None:
            sel.atom_sets.append([f.atom_id])
            where.append(f"{atom_col} = $atom_id")
            params["atom_id"] = f.atom_id
        if f.rule:
            sel.causes = cls._causes(source, f.rule)
            where.append(cls._cause_clause(sel.causes))
        hidden_where = None
        if f.hide_static:
            static = [int(r["fact"]) for r in source.rows(
                "SELECT fact FROM raw.facts WHERE static ORDER BY fact")]
            if static:
                sel.hidden_facts = static
                set_by_static = f"(cause_kind = {FACT_CAUSE} AND {cls._in('cause_id', static)})"
                hidden_where = " AND ".join([*where, set_by_static])
                where.append(f"NOT {set_by_static}")
        return cls(" AND ".join(where), params, sel, hidden_where)

    def on(self, atom_col: str) -> "TraceQuery":
        """The clause over a table whose atom id column is `atom_col` (raw.changes: atom; the changes
        view: atom_id)."""
        hidden = None if self.hidden_where is None else self.hidden_where.replace("{atom}", atom_col)
        return TraceQuery(self.where.replace("{atom}", atom_col), self.params, self.selection, hidden)

    @staticmethod
    def _in(column: str, ids: list[int]) -> str:
        return f"{column} IN ({', '.join(map(str, ids))})" if ids else "FALSE"

    @staticmethod
    def _atom_ids(source: RunSource, column: str, pattern: str) -> list[int]:
        """The atoms whose text (or label) matches the glob: resolved once against the small atoms view,
        so the scans of millions of change rows test integers."""
        return [int(r["atom"]) for r in source.rows(
            f"SELECT atom FROM atoms WHERE {column} GLOB $p ORDER BY atom", {"p": pattern})]

    @staticmethod
    def _causes(source: RunSource, pattern: str) -> list[tuple[int, list[int] | None]]:
        """(cause_kind, ids) of the causes the glob names; ids None: every cause of that kind."""
        by_kind: dict[int, list[int]] = {}
        for r in source.rows(f"SELECT kind, id FROM ({_CAUSES_SQL}) WHERE name GLOB $p ORDER BY kind, id",
                             {"p": pattern}):
            by_kind.setdefault(int(r["kind"]), []).append(int(r["id"]))
        return [(kind, None if -1 in ids else ids) for kind, ids in by_kind.items()]

    @classmethod
    def _cause_clause(cls, causes: list[tuple[int, list[int] | None]]) -> str:
        terms = [f"cause_kind = {kind}" if ids is None else f"(cause_kind = {kind} AND {cls._in('cause_id', ids)})"
                 for kind, ids in causes]
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
        self.hidden = 0                            # rows of static facts the filter leaves out
        self.grid: Grid | None = None              # the run's grid: rows get `place`, e.g. 30@(6,3)
        self.start_row = 0                         # where the table's cursor opens
        self.hints: dict[int, int] = {}
        self._raw: TraceQuery | None = None
        self._view: TraceQuery | None = None
        self._index: EpisodeIndex | None = None          # the episode's index, once attached
        self._positions: np.ndarray | range | None = None   # the filtered rows' positions in it

    def prepare(self) -> int:
        """The filtered row count (the table shows pages near a hint before the anchors exist). With the
        episode's index in memory (episode_index; read by warm()), no scan: count, start and anchors
        come from it."""
        self.grid = self.source.call(run_grid)
        query = TraceQuery.build(self.source, self.filter)
        self._raw, self._view = query.on("atom"), query.on("atom_id")
        index = cached_index(self.source, self.filter.episode)
        if index is not None and self._can_index(index):
            self._prepare_indexed(index)
            self.hidden = self._count_hidden(index)
            return self.count
        self.hidden = self._count_hidden(None)
        params, where_start = dict(self._raw.params), ""
        if self.start is not None:   # t never decreases with seq within an episode: one scan finds both
            column, params["start"] = self.start
            where_start = (f", count(*) FILTER ({column} < $start) AS at_row, "
                           f"min(seq) FILTER ({column} >= $start) AS at_seq")
        # one scan: the count, the ends, and where the start is (its row and its seq). Without a start
        # the FILTER aggregates are left out, not made FALSE: an unfiltered episode's count and seq ends
        # then take ~2 ms at 10M rows, against ~50 ms with FILTER (FALSE) (measured, sealed run)
        row = self.source.rows(f"SELECT count(*) AS n, min(seq) AS first, max(seq) AS last{where_start} "
                               f"FROM raw.changes WHERE {self._raw.where}", params)[0]
        row.setdefault("at_seq", None)
        self.count = int(row["n"])
        if self.count:
            self.hints = {0: int(row["first"]), self.count: int(row["last"]) + 1}
        if row["at_seq"] is not None:
            self.start_row = int(row["at_row"])
            self.hints[self.start_row] = int(row["at_seq"])
        elif self.start is not None and self.count:
            self.start_row = self.count - 1
        return self.count

    def _count_hidden(self, index: EpisodeIndex | None) -> int:
        """How many rows hiding static facts leaves out (from the episode's index when there is one)."""
        raw = self._raw
        if raw is None or raw.hidden_where is None:
            return 0
        if index is not None and raw.selection is not None:
            shown_all = index.positions(dataclasses.replace(raw.selection, hidden_facts=None))
            return len(shown_all) - self.count
        return int(self.source.scalar(f"SELECT count(*) FROM raw.changes WHERE {raw.hidden_where}", raw.params))

    def _can_index(self, index: EpisodeIndex) -> bool:
        return self.start is None or self.start[0] == "seq" or index.t_sorted

    def _attach(self, index: EpisodeIndex) -> None:
        """Take the filtered rows' positions and the page anchors from the episode's index."""
        assert self._raw is not None and self._raw.selection is not None
        positions = index.positions(self._raw.selection)
        self._positions, self._index = positions, index
        self.anchors = index.seq[np.asarray(positions[::PAGE], dtype=np.int64)]

    def _indexed_seq(self, row: int) -> int:
        assert self._index is not None
        assert self._positions is not None
        return int(self._index.seq[self._positions[row]])

    def _indexed_row(self, position: int) -> int:
        """The row index of the first filtered row at or after `position` in the episode."""
        positions = self._positions
        if isinstance(positions, range):
            return min(max(0, position - positions.start), len(positions))
        assert positions is not None
        return int(np.searchsorted(positions, position))

    def _prepare_indexed(self, index: EpisodeIndex) -> int:
        self._attach(index)
        assert self._positions is not None
        self.count = len(self._positions)
        if self.count:
            self.hints = {0: self._indexed_seq(0), self.count: self._indexed_seq(self.count - 1) + 1}
        if self.start is not None and self.count:
            column, value = self.start
            position = index.position_of_seq(value) if column == "seq" else index.position_of_t(value)
            assert position is not None       # _can_index: a start in t needs t sorted
            row = self._indexed_row(position)
            self.start_row = min(row, self.count - 1)
            if row < self.count:
                self.hints[row] = self._indexed_seq(row)
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
        index = episode_index(self.source, self.filter.episode)   # None for a live run
        if index is not None and self._can_index(index):
            self._attach(index)
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
        before = row - first * PAGE                # rows of the span before the hinted one
        after = min((last + 1) * PAGE, self.count) - row
        lo = bound if before <= 0 else self._edge(bound, before, forward=False)
        hi = bound if after <= 0 else self._edge(bound, after, forward=True) + 1
        return lo, hi

    def _edge(self, bound: int, n: int, forward: bool) -> int:
        """The seq of the n-th filtered row at or after `bound` (forward), or the n-th before it.

        A top-N over the whole open side scans millions of rows; a window of seq sized from the filter's
        density (its count over its seq span), doubled for slack, is pruned by the sealed file's seq
        order to a few row groups. Only if the window holds fewer than n rows (rows bunched elsewhere)
        does the unbounded query run."""
        assert self._raw is not None
        where, params = self._raw.where, {**self._raw.params, "b": bound}
        agg, side, order = ("max", "seq >= $b", "seq") if forward else ("min", "seq < $b", "seq DESC")
        span = max(1, self.hints.get(self.count, bound + 1) - self.hints.get(0, bound))
        width = 2 * n * span // max(1, self.count) + 4 * PAGE
        window = f" AND seq < $b + {width}" if forward else f" AND seq >= $b - {width}"
        for extra in (window, ""):
            found = self.source.rows(f"SELECT count(*) AS n, {agg}(seq) AS edge FROM (SELECT seq FROM "
                                     f"raw.changes WHERE {where} AND {side}{extra} ORDER BY {order} "
                                     f"LIMIT {n})", params)[0]
            if found["n"] == n or not extra:
                return int(found["edge"])
        raise AssertionError("unreachable")

    def _rows(self, lo: int, hi: int | None) -> list[dict[str, Any]]:
        """The filtered rows with lo <= seq < hi, read from the changes view (joins only these rows)."""
        assert self._view is not None
        params = {**self._view.params, "lo": lo}
        upper = ""
        if hi is not None:
            params["hi"] = hi
            upper = " AND seq < $hi"
        rows = self.source.rows(f"SELECT {TRACE_COLUMNS} FROM changes WHERE {self._view.where} "
                                f"AND seq >= $lo{upper} ORDER BY seq", params)
        grid = self.grid
        for row in rows:    # the node as shown: with its cells' (x, y) where the run declares a grid
            row["place"] = row["node"] if grid is None else grid.with_coordinates(row["node"])
        return rows

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

    def _locate_indexed(self, position: int | None) -> int | None:
        """_locate through the episode's index: the first filtered row at or after `position`."""
        if position is None:
            return None
        row = self._indexed_row(position)
        if row >= self.count:
            return None
        self.hints[row] = self._indexed_seq(row)
        return row

    def row_of_seq(self, seq: int) -> int:
        """The row index of the first filtered row with seq >= `seq` (the last row if there is none)."""
        found = self._locate_indexed(self._index.position_of_seq(seq)) if self._index is not None \
            else self._locate("seq >= $s", {"s": seq})
        return max(0, self.count - 1) if found is None else found

    def row_of_t(self, t: int) -> int:
        """The row index of the first filtered row at or after timestep t (the last row if none)."""
        found = self._locate_indexed(self._index.position_of_t(t)) \
            if self._index is not None and self._index.t_sorted else self._locate("t >= $tt", {"tt": t})
        return max(0, self.count - 1) if found is None else found

    def next_change(self, atom_id: int, seq: int, forward: bool) -> int | None:
        """The row index of the atom's next (or previous) change after (before) `seq`, if any."""
        assert self._raw is not None
        if self._index is not None:
            return self._next_change_indexed(atom_id, seq, forward)
        agg, cmp = ("min", ">") if forward else ("max", "<")
        found = self.source.scalar(f"SELECT {agg}(seq) FROM raw.changes WHERE {self._raw.where} "
                                   f"AND atom = $a AND seq {cmp} $s", {**self._raw.params, "a": atom_id, "s": seq})
        return None if found is None else self.row_of_seq(int(found))

    def _next_change_indexed(self, atom_id: int, seq: int, forward: bool) -> int | None:
        """next_change through the episode's index: the atom's rows after (before) `seq`, searched a block
        at a time from `seq` outwards, the first one the filter keeps."""
        index, positions = self._index, self._positions
        assert index is not None and positions is not None
        if not 0 <= atom_id <= index.atom_top:
            return None
        atom = index.atom.dtype.type(atom_id)   # compared at the column's width, not widened to int64
        start = int(np.searchsorted(index.seq, seq, side="right" if forward else "left"))
        step = 1 << 16
        bounds = range(start, len(index), step) if forward else range(start, 0, -step)
        for edge in bounds:
            lo, hi = (edge, min(edge + step, len(index))) if forward else (max(0, edge - step), edge)
            found = np.flatnonzero(index.atom[lo:hi] == atom) + lo
            if isinstance(positions, range):      # the filter's other conditions
                kept = found[(found >= positions.start) & (found < positions.stop)]
            else:
                rows = np.searchsorted(positions, found)
                kept = found[(rows < self.count) & (positions[np.minimum(rows, self.count - 1)] == found)] \
                    if self.count else found[:0]
            if len(kept):
                row = self._indexed_row(int(kept[0] if forward else kept[-1]))
                self.hints[row] = self._indexed_seq(row)
                return row
        return None
