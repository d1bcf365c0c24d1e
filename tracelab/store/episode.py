"""One episode's change rows in memory, indexed per atom, to answer "what was this atom's bound at this
point of the run" quickly (the why / why-not searches ask that many times).

Points in an episode: the end of timestep t (the final interpretation of t, what delayed rules read), or
just before a given row (what an immediate rule applied in that row read)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracelab.store.model import DEFAULT_BOUND
from tracelab.store.reader import RunConnection

_COLUMNS = ("seq", "t", "pass_no", "atom", "old_lower", "old_upper", "new_lower", "new_upper",
            "cause_kind", "cause_id", "grounding")


@dataclass(frozen=True)
class Row:
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
                 columns: dict[str, np.ndarray] | None = None) -> None:
        """The episode's rows up to `upto_t`, read from the run; or `columns`, the episode's rows (the
        _COLUMNS, in seq order) already read by the caller."""
        self.episode = episode
        if columns is not None:
            keep = slice(None) if upto_t is None else columns["t"] <= upto_t
            self.c = {k: np.asarray(columns[k])[keep] for k in _COLUMNS}
        else:
            sql = f"SELECT {', '.join(_COLUMNS)} FROM raw.changes WHERE episode = ?"
            params: list[int] = [episode]
            if upto_t is not None:
                sql += " AND t <= ?"
                params.append(upto_t)
            cols = con.execute(sql + " ORDER BY seq", params).fetchnumpy()
            self.c = {k: np.asarray(v) for k, v in cols.items()}
        n = len(self.c["seq"])
        self.n = n
        order = np.lexsort((self.c["seq"], self.c["atom"])) if n else np.zeros(0, np.int64)
        self._by_atom = order
        self._atom_sorted = self.c["atom"][order]

    def row(self, i: int) -> Row:
        c = self.c
        return Row(i, int(c["seq"][i]), int(c["t"][i]), int(c["pass_no"][i]), int(c["atom"][i]),
                   (float(c["old_lower"][i]), float(c["old_upper"][i])),
                   (float(c["new_lower"][i]), float(c["new_upper"][i])),
                   int(c["cause_kind"][i]), int(c["cause_id"][i]), int(c["grounding"][i]))

    def index_of_seq(self, seq: int) -> int | None:
        """The position of the change row `seq` among the episode's rows (None if it is not one)."""
        i = int(np.searchsorted(self.c["seq"], seq, "left"))
        return i if i < self.n and int(self.c["seq"][i]) == seq else None

    def _rows_of(self, atom: int) -> np.ndarray:
        lo = np.searchsorted(self._atom_sorted, atom, "left")
        hi = np.searchsorted(self._atom_sorted, atom, "right")
        return self._by_atom[lo:hi]  # row indices of this atom, in seq order

    def last_at_end_of(self, atom: int, t: int) -> Row | None:
        """The change in force at the end of timestep t (the latest with t' <= t)."""
        rows = self._rows_of(atom)
        k = np.searchsorted(self.c["t"][rows], t, "right") - 1
        return self.row(int(rows[k])) if k >= 0 else None

    def last_before(self, atom: int, index: int) -> Row | None:
        """The change in force just before row `index` of this episode."""
        rows = self._rows_of(atom)
        k = np.searchsorted(rows, index, "left") - 1
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
