"""One episode's change rows in memory, indexed per atom, to answer "what was this atom's bound at this
point of the run" quickly (the why / why-not searches ask that many times).

Points in an episode: the end of timestep t (the final interpretation of t, what delayed rules read), or
just before a given row (what an immediate rule applied in that row read)."""
from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

from tracelab.store.model import DEFAULT_BOUND
from tracelab.store.reader import RunConnection

_COLUMNS = ("seq", "t", "pass_no", "atom", "old_lower", "old_upper", "new_lower", "new_upper",
            "cause_kind", "cause_id", "grounding")
# Up to this many rows an episode is read as Python lists, which needs no numpy (~0.15 s of CPU to import:
# a `why` on a small run starts about as fast as DuckDB does); a bigger one as numpy arrays (8 bytes a
# value, not ~30, and no Python object per value). The searches read both alike (bisect, indexing).
PYTHON_ROWS = 100_000


class Row(NamedTuple):
    index: int  # position in the episode's rows (seq order)
    seq: int
    t: int
    pass_no: int
    atom: int
    old: tuple[float, float]
    new: tuple[float, float]
    cause_kind: int
    cause_id: int
    grounding: int


class EpisodeTrace:
    def __init__(self, con: RunConnection, episode: int, upto_t: int | None = None,
                 columns: Mapping[str, Sequence[Any]] | None = None) -> None:
        """The episode's rows up to `upto_t`, read from the run; or `columns`, the episode's rows (the
        _COLUMNS, in seq order, so in t order) already read by the caller."""
        self.episode = episode
        if columns is not None:
            cut = len(columns["t"]) if upto_t is None else bisect_right(columns["t"], upto_t)
            self.c = {k: columns[k][:cut] for k in _COLUMNS}
        else:
            self.c = _read_columns(con, episode, upto_t)
        self.n = len(self.c["seq"])
        # row indices in (atom, seq) order: a stable sort by atom of rows in seq order
        atom = self.c["atom"]
        self._by_atom = atom.argsort(kind="stable") if hasattr(atom, "argsort") else \
            sorted(range(self.n), key=atom.__getitem__)

    def row(self, i: int) -> Row:
        c = self.c
        return Row(i, int(c["seq"][i]), int(c["t"][i]), int(c["pass_no"][i]), int(c["atom"][i]),
                   (float(c["old_lower"][i]), float(c["old_upper"][i])),
                   (float(c["new_lower"][i]), float(c["new_upper"][i])),
                   int(c["cause_kind"][i]), int(c["cause_id"][i]), int(c["grounding"][i]))

    def index_of_seq(self, seq: int) -> int | None:
        """The position of the change row `seq` among the episode's rows (None if it is not one)."""
        i = bisect_left(self.c["seq"], seq)
        return i if i < self.n and int(self.c["seq"][i]) == seq else None

    def _rows_of(self, atom: int) -> Sequence[int]:
        key = self.c["atom"].__getitem__
        lo = bisect_left(self._by_atom, atom, key=key)
        hi = bisect_right(self._by_atom, atom, lo=lo, key=key)
        return self._by_atom[lo:hi]  # row indices of this atom, in seq order

    def last_at_end_of(self, atom: int, t: int) -> Row | None:
        """The change in force at the end of timestep t (the latest with t' <= t)."""
        rows = self._rows_of(atom)
        k = bisect_right(rows, t, key=self.c["t"].__getitem__) - 1
        return self.row(int(rows[k])) if k >= 0 else None

    def changes_at(self, atom: int, t: int) -> list[tuple[int, int]]:
        """(pass, seq) of each change of `atom` at timestep t, in order."""
        rows, at_t = self._rows_of(atom), self.c["t"].__getitem__
        lo = bisect_left(rows, t, key=at_t)
        return [(int(self.c["pass_no"][i]), int(self.c["seq"][i]))
                for i in rows[lo:bisect_right(rows, t, lo=lo, key=at_t)]]

    def last_before(self, atom: int, index: int) -> Row | None:
        """The change in force just before row `index` of this episode."""
        rows = self._rows_of(atom)
        k = bisect_left(rows, index) - 1
        return self.row(int(rows[k])) if k >= 0 else None

    def ordinary_pass_start(self, index: int, immediate_rules: set[int]) -> int:
        """The first row of the ordinary pass that row `index` belongs to: the rows an ordinary pass
        applies together all read the interpretation from before the first of them."""
        c = self.c
        t, p = c["t"][index], c["pass_no"][index]
        i = index
        while i > 0 and c["t"][i - 1] == t and c["pass_no"][i - 1] == p and (
                c["cause_kind"][i - 1] == 3 or
                (c["cause_kind"][i - 1] == 2 and int(c["cause_id"][i - 1]) not in immediate_rules)):
            i -= 1
        return i

    @staticmethod
    def bound(row: Row | None) -> tuple[float, float]:
        return row.new if row is not None else DEFAULT_BOUND


def _read_columns(con: RunConnection, episode: int, upto_t: int | None) -> dict[str, Sequence[Any]]:
    """The episode's _COLUMNS up to `upto_t` in seq order: lists, or numpy arrays past PYTHON_ROWS rows."""
    where, params = "WHERE episode = ?", [episode]
    if upto_t is not None:
        where += " AND t <= ?"
        params.append(upto_t)
    select = f"SELECT {', '.join(_COLUMNS)} FROM raw.changes {where} ORDER BY seq"
    # one statement for an episode of Python lists; a bigger one is read again, as numpy arrays
    rows = con.execute(f"{select} LIMIT {PYTHON_ROWS + 1}", params).fetchall()
    if len(rows) > PYTHON_ROWS:
        return dict(con.execute(select, params).fetchnumpy())  # DuckDB imports numpy for it
    return {k: list(column) for k, column in zip(_COLUMNS, zip(*rows))} if rows else {k: [] for k in _COLUMNS}
