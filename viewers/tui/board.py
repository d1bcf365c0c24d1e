"""BoardView: the grid world at the trace's cursor, beside the trace (tracelab.viewers.board rebuilds it from
the run's change rows). Team-coloured agents (R1, B1; ✕ when dead), bullets as arrows, mountains, bases,
and under the grid each agent's health, ammo and action. It follows the cursor to the phase of the
selected change within its step. A run that is not a grid-world game shows a note instead."""
from __future__ import annotations

from typing import Any

from rich.text import Text
from textual.widget import Widget

from tracelab.viewers.board import DIRECTIONS, NO_ACTION, PHASES, BoardLoader, EpisodeBoard
from tracelab.viewers.tui.colours import BLUE_TEAM, DIM, MOUNTAIN, RED_TEAM
from tracelab.viewers.tui.source import RunSource

TEAM_COLOURS = (RED_TEAM, BLUE_TEAM)
ARROWS = {"up": "↑", "down": "↓", "left": "←", "right": "→"}
ACTIONS = ("up", "down", "left", "right", "shoot↑", "shoot↓", "shoot←", "shoot→", "stay")


def _short(name: str) -> str:
    """red-agent-1 -> R1."""
    digits = "".join(p for p in name.split("-")[2:] if p.isdigit())
    return (name[0].upper() + digits)[:2]


def draw(board: EpisodeBoard, step: int, phase: int = -1) -> Text:
    """The board at the end of `phase` of `step` as text: two characters a cell, y up."""
    frame = board.frame(step, phase)
    w, h = board.map.width, board.map.height
    cells: dict[tuple[int, int], tuple[str, str]] = {}
    for x, y in board.map.mountains.tolist():
        cells[(x, y)] = ("▲▲", MOUNTAIN)
    for team, (x, y) in enumerate(board.map.bases.tolist()):
        cells[(x, y)] = ("[]", f"{TEAM_COLOURS[team]}")
    for b in frame.bullets:
        cells[(b.x, b.y)] = (" " + ARROWS[DIRECTIONS[b.direction]], f"bold {TEAM_COLOURS[b.team == 'blue']}")
    for a in frame.agents:
        colour = TEAM_COLOURS[a.team == "blue"]
        cells[(a.x, a.y)] = (_short(a.name), f"bold white on {colour}") if a.alive else ("✕ ", f"{colour}")
    text = Text()
    text.append(f"step {step} · {PHASES[phase % len(PHASES)]}\n", style="bold")
    for y in range(h - 1, -1, -1):
        for x in range(w):
            glyph, style = cells.get((x, y), ("· ", DIM))
            text.append(glyph, style=style)
        text.append("\n")
    for a in frame.agents:
        colour = TEAM_COLOURS[a.team == "blue"]
        act = "" if a.action == NO_ACTION else ACTIONS[a.action] if 0 <= a.action < len(ACTIONS) else str(a.action)
        state = f"♥{a.health:g} ammo {a.ammo}" if a.alive else "dead"
        text.append(f"{_short(a.name)}", style=f"bold {colour}")
        text.append(f" {state} {act}\n")
    return text


class BoardView(Widget):
    DEFAULT_CSS = """
    BoardView { width: 22; height: 1fr; border: round $primary-darken-2; padding: 0 0; }
    """

    def __init__(self, source: RunSource) -> None:
        super().__init__()
        self.source = source
        self.border_title = "board"
        self.board: EpisodeBoard | None = None
        self.step, self.phase = 0, -1
        self.note = "select a change"
        self._loader: BoardLoader | None = None
        self._loading: int | None = None
        self._want: tuple[int, int, int] | None = None

    def show(self, episode: int, t: int, seq: int) -> None:
        """Follow the trace's cursor: the board of `episode` at timestep t, at the phase of change seq."""
        self._want = (episode, t, seq)
        if self.board is not None and self.board.episode == episode:
            self._place()
        elif self._loading != episode:
            self._loading = episode
            self.run_worker(lambda: self._load(episode), thread=True, group="board", exclusive=True,
                            exit_on_error=False)

    def _load(self, episode: int) -> None:
        def load(con: Any) -> EpisodeBoard:
            if self._loader is None:
                self._loader = BoardLoader(con)
            return self._loader.load(episode)
        try:
            board, note = self.source.call(load), ""
        except Exception as e:  # noqa: BLE001 - not a game run, or no rows: a note, not a crash
            board, note = None, str(e).splitlines()[0] if str(e) else type(e).__name__
        self.app.call_from_thread(self._loaded, episode, board, note)

    def _loaded(self, episode: int, board: EpisodeBoard | None, note: str) -> None:
        self._loading = None
        self.board, self.note = board, note
        if board is not None:
            self._place()
        self.refresh(layout=True)   # beside the decision panel its height is its content's

    def _place(self) -> None:
        assert self.board is not None and self._want is not None
        _, t, seq = self._want
        self.step = max(0, min(self.board.steps, t))
        f = self.board.firings
        rows = [i for i in f.at(self.step) if int(f.seq[i]) == seq]
        self.phase = int(f.phase[rows[0]]) if rows else -1
        self.refresh()

    def render(self) -> Text:
        if self.board is None:
            return Text(self.note, style="italic dim")
        return draw(self.board, self.step, self.phase)
