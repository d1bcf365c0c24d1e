"""BoardView: a run's board at the trace cursor's timestep, beside the trace: the spec's `[board]`
(tracelab.board; an older run's without a spec: viewers/board_state.py), each cell's character in
its colour, a mark's character where its predicate holds (FrozenLake's `@`), the pieces where they stand
(war.toml's agents R1, B1 in their team's colour, ✕ when dead; its bullets as arrows) and under the grid
each living or dead piece of a kind with `alive`. A cell is one character, two when the board has pieces
(a label). The trace shows it for every run whose world has a board (RunSource.board); a read that
fails shows a note instead."""
from __future__ import annotations


from rich.text import Text
from textual.widget import Widget

from tracelab.board import Board, piece_label
from tracelab.viewers.board_state import BoardState, BoardTrack
from tracelab.viewers.tui.colours import DIM
from tracelab.viewers.tui.source import RunSource, background

SHADE = 0.3      # a terrain cell's background: its colour this bright


def _hex(rgb: tuple[int, int, int] | None) -> str:
    return "" if rgb is None else "#{:02x}{:02x}{:02x}".format(*rgb)


def _cell_style(rgb: tuple[int, int, int] | None) -> str:
    """A terrain cell: its colour on a dark shade of it (a board's light floor stays calm on a dark
    terminal, a dark mountain still shows)."""
    if rgb is None:
        return DIM
    return f"{_hex(rgb)} on {_hex(tuple(int(v * SHADE) for v in rgb))}"  # type: ignore[arg-type]


def drawn_width(board: Board) -> int:
    """The columns `draw` takes: a cell is two wide when the board has pieces; a piece's line under the grid
    (`R1 alive`) eight."""
    return max(board.width * (2 if board.pieces else 1), 8 if any(k.alive for k in board.pieces.values()) else 0)


def draw(board: Board, state: BoardState) -> Text:
    """The board at the end of `state.t` as text, top row first."""
    wide = bool(board.pieces)
    on: dict[tuple[int, int], tuple[str, str]] = {}
    for p in state.pieces:                    # later kinds (bullets) over earlier ones only where alone
        colour = _hex(board.pieces[p.kind].color(p.thing)) or "white"
        if p.arrow:
            glyph = (" " + p.arrow, f"bold {colour}")
        elif p.alive:
            glyph = (piece_label(p.thing).ljust(2), f"bold white on {colour}")
        else:
            glyph = ("✕ ", colour)
        if (p.row, p.col) not in on or p.alive and not p.arrow:
            on[(p.row, p.col)] = glyph if wide else (glyph[0].strip()[:1] or "?", glyph[1])
    text = Text()
    for r, line in enumerate(board.rows):
        if r:
            text.append("\n")
        for c, ch in enumerate(line):
            pred = state.marked.get(board.cell(r, c))
            if (r, c) in on:
                text.append(*on[(r, c)])
            elif pred:
                text.append(board.marks[pred] + (" " if wide else ""), style="bold reverse")
            else:
                shown = "·" if ch == "." else ch
                text.append(shown + (" " if wide else ""), style=_cell_style(board.colors.get(ch)))
    for p in state.pieces:
        if board.pieces[p.kind].alive:
            text.append("\n")
            text.append(piece_label(p.thing), style=f"bold {_hex(board.pieces[p.kind].color(p.thing))}")
            text.append(f" {'alive' if p.alive else 'dead'}")
    return text


class BoardView(Widget):
    def __init__(self, source: RunSource, board: Board) -> None:
        super().__init__(id="board")
        self.source = source
        self.border_title = "board"
        self.declared = board                 # the run's board (RunSource.board)
        self.board: BoardTrack | None = None  # the episode's board over time (tests read it)
        self.step = 0
        self.note = "select a change"
        self._loading: int | None = None
        self._want: tuple[int, int] | None = None

    def show(self, episode: int, t: int, seq: int | None = None) -> None:
        """Follow the trace's cursor: the board of `episode` at the end of timestep t."""
        self._want = (episode, t)
        if self.board is not None and self.board.episode == episode:
            self._place()
        elif self._loading != episode:
            self._loading = episode
            self.run_worker(background(lambda: self._load(episode)), thread=True, group="board", exclusive=True,
                            exit_on_error=False)

    def _load(self, episode: int) -> None:
        try:
            track, note = self.source.call(lambda con: BoardTrack.read(con, self.declared, episode)), ""
        except Exception as e:  # noqa: BLE001 - a run that cannot be read: a note, not a crash
            track, note = None, str(e).splitlines()[0] if str(e) else type(e).__name__
        self.app.call_from_thread(self._loaded, track, note)

    def _loaded(self, track: BoardTrack | None, note: str) -> None:
        self._loading = None
        self.board, self.note = track, note
        if track is not None:
            self._place()
        self.refresh(layout=True)

    def _place(self) -> None:
        assert self.board is not None and self._want is not None
        self.step = max(0, self._want[1])
        self.border_title = f"board at t={self.step}"
        self.refresh(layout=True)

    def render(self) -> Text:
        if self.board is None:
            return Text(self.note, style=f"italic {DIM}")
        return draw(self.declared, self.board.at(self.step))
