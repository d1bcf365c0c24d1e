"""The board of a declared world's run (`tracelab play --env`, docs/worlds.md) above the atoms beside the
trace: the spec's rows, each cell's character replaced by its mark where the mark's predicate holds at
the cursor's t (FrozenLake's `@` where `at(C)` is true). The board is the one the run's config records
(tracelab.board, which the replay and `rgb_array` draw too); a run without one shows
nothing here."""
from __future__ import annotations

from rich.text import Text
from textual.widget import Widget

from tracelab.board import Board
from tracelab.viewers.tui.colours import DIM


class DeclaredBoard(Widget):
    DEFAULT_CSS = "DeclaredBoard { height: auto; max-height: 50%; border: round $primary-darken-2; }"

    def __init__(self, board: Board) -> None:
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
        out = Text()
        for r, line in enumerate(self.board.rows):
            if r:
                out.append("\n")
            for c, ch in enumerate(line):
                pred = self.marked.get(self.board.cell(r, c))
                out.append(self.board.marks[pred] if pred else ch, style="bold reverse" if pred else "")
        return out
