"""EpisodeIndex: the columns the trace filters test (seq, t, atom, cause kind and id) of one episode of a
sealed run, in memory as numpy arrays in seq order, so that a filter's count, its rows' positions and its
page anchors are a few vectorised passes (~10-40 ms at 10M rows, whatever the database's load) instead of
full scans of the change table per filter.

It is read once per episode, in the background (the trace table's warm-up), through the run's sandboxed
connection, and kept for the last episode only (a 10M-row episode takes ~130 MB). Live runs get none:
their episodes grow, and the SQL path (paging.TraceSource) serves them."""
from __future__ import annotations

import threading
import weakref
from dataclasses import dataclass

import numpy as np

from tracelab.store.reader import query_readonly
from tracelab.viewers.tui.source import RunSource

# (NULL cause ids, if any, as -1: never a resolved id, as NULL never equals one in SQL)
_COLUMNS = "seq, t, atom, cause_kind, coalesce(cause_id, -1) AS cause_id"


@dataclass
class RowSelection:
    """What a filter keeps, as resolved ids: every atom set must hold the row's atom; `causes` is None
    (any cause) or (cause_kind, cause ids or None for any id) pairs of which one must match."""
    atom_sets: list[list[int]]
    causes: list[tuple[int, list[int] | None]] | None
    t_from: int | None = None
    t_to: int | None = None


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
        self.cause_id = pick(np.asarray(columns["cause_id"], dtype=np.int32))
        # t never decreases with seq within an episode (the engine's clock); checked, not assumed
        self.t_sorted = len(self.t) < 2 or bool(np.all(self.t[1:] >= self.t[:-1]))

    def __len__(self) -> int:
        return len(self.seq)

    def positions(self, sel: RowSelection) -> np.ndarray | None:
        """The positions (in seq order) of the rows `sel` keeps; None means every row."""
        mask: np.ndarray | None = None

        def keep(m: np.ndarray) -> None:
            nonlocal mask
            mask = m if mask is None else mask & m

        for ids in sel.atom_sets:
            keep(_lookup(self.atom, ids))
        if sel.causes is not None:
            m = np.zeros(len(self), dtype=bool)
            for kind, ids in sel.causes:
                k = self.cause_kind == kind
                m |= k if ids is None else k & _lookup(self.cause_id, ids)
            keep(m)
        lo, hi = 0, len(self)
        if self.t_sorted:    # a time range is a slice
            if sel.t_from is not None:
                lo = int(np.searchsorted(self.t, sel.t_from, side="left"))
            if sel.t_to is not None:
                hi = int(np.searchsorted(self.t, sel.t_to, side="right"))
        else:
            if sel.t_from is not None:
                keep(self.t >= sel.t_from)
            if sel.t_to is not None:
                keep(self.t <= sel.t_to)
        if mask is None:
            return None if (lo, hi) == (0, len(self)) else np.arange(lo, max(lo, hi), dtype=np.int64)
        return np.flatnonzero(mask[lo:hi]) + lo if (lo, hi) != (0, len(self)) else np.flatnonzero(mask)

    def position_of_seq(self, seq: int) -> int:
        """The position of the first row with seq >= `seq`."""
        return int(np.searchsorted(self.seq, seq, side="left"))

    def position_of_t(self, t: int) -> int | None:
        """The position of the first row at or after timestep t (None if t is not sorted)."""
        return int(np.searchsorted(self.t, t, side="left")) if self.t_sorted else None


def _lookup(values: np.ndarray, ids: list[int]) -> np.ndarray:
    """values ∈ ids, through a boolean table over the id range (one gather, not a hash per row)."""
    if not ids or len(values) == 0:
        return np.zeros(len(values), dtype=bool)
    top = max(int(values.max()), max(ids)) + 1
    table = np.zeros(top + 1, dtype=bool)
    wanted = np.asarray([i for i in ids if i >= 0], dtype=np.int64)
    table[wanted] = True
    if int(values.min()) < 0:        # e.g. cause_id -1: never one of the resolved ids
        return np.where(values >= 0, table[np.maximum(values, 0)], False)
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
            columns = source.call(lambda con: query_readonly(
                con, f"SELECT {_COLUMNS} FROM raw.changes WHERE episode = $e",
                {"e": episode}).fetchnumpy())
            index = EpisodeIndex(episode, columns)
            _CACHE[source] = index
        return index
