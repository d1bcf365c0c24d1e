"""EpisodeIndex: the columns the trace filters test (seq, t, atom, cause kind and id) of one episode of a
sealed run, in memory as numpy arrays in seq order, so that a filter's count, its rows' positions and its
page anchors are a few vectorised passes (~10-40 ms at 10M rows, whatever the database's load) instead of
full scans of the change table per filter.

It is read once per episode, in the background (the trace table's warm-up), through the run's sandboxed
connection, and kept for the last episode only (a 10M-row episode takes ~170 MB). Live runs get none:
their episodes grow, and the SQL path (trace_paging.TraceSource) serves them."""
from __future__ import annotations

import threading
import weakref
from dataclasses import dataclass

import numpy as np

from tracelab.store.reader import query_readonly
from tracelab.store.static_facts import FACT_CAUSE
from tracelab.viewers.tui.source import RunSource

# (NULL or negative cause ids, if any, as -1: never a resolved id, as in SQL)
_COLUMNS = "seq, t, atom, cause_kind, greatest(coalesce(cause_id, -1), -1) AS cause_id"


@dataclass
class RowSelection:
    """What a filter keeps, as resolved ids: every atom set must hold the row's atom; `causes` is None
    (any cause) or (cause_kind, cause ids or None for any id) pairs of which one must match; the rows set
    by one of `hidden_facts` (fact ids: the static facts, when hidden) are left out."""
    atom_sets: list[list[int]]
    causes: list[tuple[int, list[int] | None]] | None
    t_from: int | None = None
    t_to: int | None = None
    hidden_facts: list[int] | None = None


class EpisodeIndex:
    def __init__(self, episode: int, columns: dict[str, np.ndarray]) -> None:
        self.episode = episode
        order = None
        seq = np.asarray(columns["seq"], dtype=np.int64)
        if len(seq) > 1 and not bool(np.all(seq[1:] > seq[:-1])):   # a sealed run stores them sorted
            order = np.argsort(seq, kind="stable")
        pick = (lambda a: a) if order is None else (lambda a: a[order])
        self.seq = pick(seq)
        self.t = pick(np.asarray(columns["t"], dtype=np.int32))
        self.atom = pick(np.asarray(columns["atom"], dtype=np.int32))
        self.cause_kind = pick(np.asarray(columns["cause_kind"], dtype=np.int8))
        # cause id + 1, so that a NULL id (-1) indexes slot 0 of a lookup table (never a resolved id)
        self.cause_slot = pick(np.asarray(columns["cause_id"], dtype=np.int32) + 1)
        # the id ranges, for the lookup tables (one pass now instead of one per filter)
        self.atom_top = int(self.atom.max()) if len(self.atom) else 0
        if len(self.atom) and int(self.atom.min()) < 0:
            raise ValueError(f"episode {episode} has negative atom ids: not indexable")
        self.cause_top = int(self.cause_slot.max()) if len(self.cause_slot) else 0
        # narrower ids where they fit: a 10M-row episode takes ~170 MB instead of ~210 MB
        if self.atom_top < 2**15:
            self.atom = self.atom.astype(np.int16)
        if self.cause_top < 2**15:
            self.cause_slot = self.cause_slot.astype(np.int16)
        # t never decreases with seq within an episode (the engine's clock); checked, not assumed
        self.t_sorted = len(self.t) < 2 or bool(np.all(self.t[1:] >= self.t[:-1]))

    def __len__(self) -> int:
        return len(self.seq)

    def positions(self, sel: RowSelection) -> np.ndarray | range:
        """The positions (in seq order) of the rows `sel` keeps, ascending (a range when no id is
        tested: a time range alone is a slice)."""
        lo, hi = 0, len(self)
        t_tested = False                 # the time range, tested row by row (t not sorted)
        if self.t_sorted:
            if sel.t_from is not None:
                lo = self._t_position(sel.t_from, "left")
            if sel.t_to is not None:
                hi = max(lo, self._t_position(sel.t_to, "right"))
        else:
            t_tested = sel.t_from is not None or sel.t_to is not None
        if not sel.atom_sets and sel.causes is None and not sel.hidden_facts and not t_tested:
            return range(lo, hi)
        part = slice(lo, hi)
        mask: np.ndarray | None = None

        def keep(m: np.ndarray) -> None:
            nonlocal mask
            mask = m if mask is None else np.logical_and(mask, m, out=mask)

        for ids in sel.atom_sets:
            keep(_lookup(self.atom[part], ids, self.atom_top, 0))
        if sel.causes is not None:
            kinds = self.cause_kind[part]
            anyof: np.ndarray | None = None
            for kind, ids in sel.causes:
                term = kinds == kind
                if ids is not None:
                    term &= _lookup(self.cause_slot[part], ids, self.cause_top, 1)
                anyof = term if anyof is None else np.logical_or(anyof, term, out=anyof)
            keep(np.zeros(hi - lo, dtype=bool) if anyof is None else anyof)
        if sel.hidden_facts:
            set_by_fact = self.cause_kind[part] == FACT_CAUSE
            set_by_fact &= _lookup(self.cause_slot[part], sel.hidden_facts, self.cause_top, 1)
            keep(~set_by_fact)
        if t_tested:
            if sel.t_from is not None:
                keep(self.t[part] >= sel.t_from)
            if sel.t_to is not None:
                keep(self.t[part] <= sel.t_to)
        assert mask is not None
        found = np.flatnonzero(mask)
        return found + lo if lo else found

    def position_of_seq(self, seq: int) -> int:
        """The position of the first row with seq >= `seq`."""
        return int(np.searchsorted(self.seq, seq, side="left"))

    def position_of_t(self, t: int) -> int | None:
        """The position of the first row at or after timestep t (None if t is not sorted)."""
        return self._t_position(t, "left") if self.t_sorted else None

    def _t_position(self, t: int, side: str) -> int:
        # as int32: a Python int would make numpy convert the whole column to int64 first (~25 ms)
        bound = np.int32(min(max(t, -2**31), 2**31 - 1))
        return int(np.searchsorted(self.t, bound, side=side))  # type: ignore[call-overload]


def _lookup(values: np.ndarray, ids: list[int], top: int, offset: int) -> np.ndarray:
    """(values - offset) ∈ ids, for 0 <= values <= top, through a boolean table over the id range: one
    gather, not a hash per row."""
    table = np.zeros(top + 1, dtype=bool)
    wanted = np.asarray([i + offset for i in ids if 0 <= i + offset <= top], dtype=np.int64)
    table[wanted] = True
    return table[values]


# The last episode index of each open run (one per run bounds the memory), and a lock per run so that
# two warm-ups of the same episode read it once.
_CACHE: "weakref.WeakKeyDictionary[RunSource, EpisodeIndex]" = weakref.WeakKeyDictionary()
_LOCKS: "weakref.WeakKeyDictionary[RunSource, threading.Lock]" = weakref.WeakKeyDictionary()
_GUARD = threading.Lock()


def cached_index(source: RunSource, episode: int) -> EpisodeIndex | None:
    """The episode's index if it has been read (never reads it)."""
    index = _CACHE.get(source)
    return index if index is not None and index.episode == episode else None


def episode_index(source: RunSource, episode: int) -> EpisodeIndex | None:
    """The episode's index, read now if needed; None for a live run (its episodes still grow)."""
    if source.live:
        return None
    with _GUARD:
        lock = _LOCKS.setdefault(source, threading.Lock())
    with lock:
        index = cached_index(source, episode)
        if index is None:
            table = source.call(lambda con: query_readonly(
                con, f"SELECT {_COLUMNS} FROM raw.changes WHERE episode = $e",
                {"e": episode}).to_arrow_table())
            # through Arrow: about half the time of fetchnumpy() (no column here has NULLs)
            columns = {name: table.column(name).to_numpy() for name in table.column_names}
            del table
            try:
                index = EpisodeIndex(episode, columns)
            except ValueError:      # the SQL path serves it
                return None
            _CACHE[source] = index
        return index
