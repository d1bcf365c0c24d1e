"""What kind of run a run is, as the run itself says: the board it declares in its metadata
(RunMeta.board, the `board` column of the `run` view). A game run declares its board and viewers draw its
episodes on it; a run without a board (a reasoning run, `tracelab reason --run`) has only its trace,
program and graph. The store reads no game's vocabulary to tell them apart."""
from __future__ import annotations

from tracelab.store.reader import RunConnection


def run_board(con: RunConnection) -> str | None:
    """The board the run declares, or None (runs written before boards were declared read as the grid
    game's: schema.BOARD_BEFORE_DECLARED)."""
    rows = con.execute("SELECT board FROM raw.run").fetchall()
    return rows[0][0] if rows else None


def has_board(con: RunConnection) -> bool:
    return run_board(con) is not None
