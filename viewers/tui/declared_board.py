"""The board of a declared world's run (`tracelab play --env`, docs/worlds.md) above the atoms beside the
trace: the spec's rows, each cell's character replaced by its mark where the mark's predicate holds at
the cursor's t (FrozenLake's `@` where `at(C)` is true). The run declares it in its config
(`declared_board`: rows, the cell constants' format, marks); a run without it shows nothing here.
A run's config comes from anywhere: it is checked (types, sizes) and the cell format is filled in by
plain replacement, never str.format."""
from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from rich.text import Text
from textual.widget import Widget

from tracelab.viewers.tui.colours import DIM

CONFIG_KEY = "declared_board"
MAX_SIDE = 256  # rows and columns drawn at most (the spec's own limit is 256 x 256 cells)


@dataclass(frozen=True)
class BoardRows:
    rows: tuple[str, ...]
    cell_format: str
    marks: dict[str, str]  # predicate -> its one-character mark

    def cell(self, row: int, col: int) -> str:
        return self.cell_format.replace("{row}", str(row)).replace("{col}", str(col))

    def text(self, marked: dict[str, str]) -> Text:
        """The rows, a cell's character replaced by the mark of the predicate true there (`marked`: cell
        constant -> predicate)."""
        out = Text()
        for r, line in enumerate(self.rows):
            if r:
                out.append("\n")
            for c, ch in enumerate(line):
                pred = marked.get(self.cell(r, c))
                out.append(self.marks[pred] if pred else ch, style="bold reverse" if pred else "")
        return out


def board_of_config(config: Any) -> BoardRows | None:
    """The board a run's config declares, or None (none declared, or a declaration that does not hold)."""
    doc = config.get(CONFIG_KEY) if isinstance(config, dict) else None
    if not isinstance(doc, dict):
        return None
    rows, cell, marks = doc.get("rows"), doc.get("cell"), doc.get("marks")
    ok = (isinstance(rows, list) and 0 < len(rows) <= MAX_SIDE and all(isinstance(r, str) and len(r) <= MAX_SIDE
                                                                       for r in rows)
          and isinstance(cell, str) and len(cell) <= 100 and isinstance(marks, dict)
          and all(isinstance(k, str) and k.isidentifier() and isinstance(v, str) and len(v) == 1
                  for k, v in marks.items()))
    return BoardRows(tuple(rows), cell, dict(marks)) if ok else None


def run_board_rows(con: Any) -> BoardRows | None:
    """The declared board of the run open on `con`, or None."""
    rows = con.execute("SELECT config FROM raw.run").fetchall()
    try:
        return board_of_config(json.loads(rows[0][0])) if rows and rows[0][0] else None
    except (TypeError, ValueError):
        return None


def marked_cells(board: BoardRows, true_atoms: dict[str, list[str]]) -> dict[str, str]:
    """Cell constant -> the mark predicate true there, from each mark predicate's true atoms' texts
    (`at(c1_2)`)."""
    out: dict[str, str] = {}
    for pred, atoms in true_atoms.items():
        for atom in atoms:
            if atom.startswith(pred + "(") and atom.endswith(")"):
                out[atom[len(pred) + 1:-1]] = pred
    return out


class DeclaredBoard(Widget):
    DEFAULT_CSS = "DeclaredBoard { height: auto; max-height: 50%; border: round $primary-darken-2; }"

    def __init__(self, board: BoardRows) -> None:
        super().__init__(id="gs-board")
        self.board = board
        self.border_title = "board"
        self.marked: dict[str, str] | None = None  # what is drawn (tests read it)

    def show(self, t: int, marked: dict[str, str]) -> None:
        self.marked = marked
        self.border_title = f"board at t={t}"
        self.refresh(layout=True)

    def render(self) -> Text:
        if self.marked is None:
            return Text("select a change", style=f"italic {DIM}")
        return self.board.text(self.marked)
