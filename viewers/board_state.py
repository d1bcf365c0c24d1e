"""A run's board over an episode, for the viewers (the TUI's board, the replay's): the spec's `[board]`
(tracelab.board) and, at the end of each timestep t, its marks and its pieces (where each thing stands,
alive or dead, which way it heads), read from the run's changes of the board's predicates.

Which board: the one the run's config records (a spec world's run: `tracelab play --env`, a training's
evaluation games); a run an earlier tracelab wrote, with no spec among its sources, is drawn with the
board its world's registration gives (world_extras.old_run_board: the war game's RuleSim runs on
war.toml's `[board]`). Such a run names its cells by id (y·W + x, its declared grid:
tracelab.store.coordinates), a spec's run by the board's cell constants: both are located.

    board = board_of_run(con)
    track = BoardTrack.read(con, board, episode)
    track.at(5).pieces        # the Piece list at the end of t = 5
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass
from typing import Any

from tracelab.board import DIRECTION_ARROWS, Board, board_of_config
from tracelab.store.coordinates import Grid, run_grid
from tracelab.store.kind import run_board, run_config, spec_text
from tracelab.store.reader import RunConnection
from tracelab.world_extras import old_run_board



@dataclass(frozen=True)
class Piece:
    kind: str                    # the `[board.pieces]` name
    thing: str
    row: int
    col: int
    alive: bool
    arrow: str                   # the heading's arrow, "" without one


@dataclass(frozen=True)
class BoardState:
    """The board at the end of timestep t: cell constant -> its mark's predicate, and the pieces on it."""
    t: int
    marked: dict[str, str]
    pieces: list[Piece]


def board_of_run(con: RunConnection) -> Board | None:
    """The board to draw a run's episodes on, or None (a run without one: a reasoning, a world without a
    `[board]`)."""
    config = run_config(con)
    board = board_of_config(config)
    if board is not None or spec_text(con, config) is not None:
        return board
    return old_run_board(run_board(con), config)  # an older run of a world: its registration's


def locator(board: Board, grid: Grid | None) -> dict[str, tuple[int, int]]:
    """Node name -> (row, col) of each board cell: the board's constants, and a run's cell ids (y·W + x)
    when the run declares a grid of the board's size."""
    out = {name: divmod(i, board.width) for i, name in enumerate(board.cells)}
    if grid is not None and (grid.width, grid.height) == (board.width, board.height):
        out.update({str(y * board.width + x): (board.height - 1 - y, x)
                    for y in range(board.height) for x in range(board.width)})
    return out


@dataclass
class BoardTrack:
    """An episode's board state at each timestep where it changed (`at` takes the last one at or before t)."""
    board: Board
    episode: int
    times: list[int]
    states: list[BoardState]
    cells: dict[str, tuple[int, int]]

    @classmethod
    def read(cls, con: RunConnection, board: Board, episode: int) -> BoardTrack:
        # an older run (its board its world's registration's: none in its config, no spec) names its cells
        # y·W + x of its own map (a training run's config may not declare it)
        config = run_config(con)
        older = board_of_config(config) is None and spec_text(con, config) is None
        grid = run_grid(con) or (Grid(board.width, board.height) if older else None)
        cells = locator(board, grid)
        kinds = _thing_kinds(con, board)
        preds = sorted({*board.marks, *(p for k in board.pieces.values() for p in k.predicates)})
        rows = con.execute(
            "SELECT c.t, l.name, n0.name, n1.name, c.new_lower >= 1 FROM raw.changes c "
            "JOIN raw.atoms a ON a.atom = c.atom JOIN raw.labels l ON l.label = a.label "
            "JOIN raw.nodes n0 ON n0.node = a.arg0 LEFT JOIN raw.nodes n1 ON n1.node = a.arg1 "
            "WHERE c.episode = ? AND l.name IN (SELECT unnest(?::VARCHAR[])) ORDER BY c.seq",
            [episode, preds]).fetchall()
        marks: dict[str, set[str]] = {p: set() for p in board.marks}
        where: dict[str, str] = {}           # thing -> its cell node
        alive: dict[str, bool] = {}
        heading: dict[str, str] = {}
        times: list[int] = []
        states: list[BoardState] = []

        def snapshot(t: int) -> None:
            marked = {cell: p for p in board.marks for cell in sorted(marks[p])}
            pieces = []
            for thing, node in where.items():
                kind = kinds.get(thing)
                if kind is None or node not in cells:
                    continue
                spec = board.pieces[kind]
                r, c = cells[node]
                pieces.append(Piece(kind, thing, r, c, alive.get(thing, False) if spec.alive else True,
                                    DIRECTION_ARROWS.get(heading.get(thing, ""), "") if spec.heading else ""))
            pieces.sort(key=lambda p: (list(board.pieces).index(p.kind), _ordinal(p.thing)))
            times.append(t)
            states.append(BoardState(t, marked, pieces))

        at_preds = {k.at for k in board.pieces.values()}
        alive_preds = {k.alive for k in board.pieces.values() if k.alive}
        heading_preds = {k.heading for k in board.pieces.values() if k.heading}
        last = None
        for t, pred, a0, a1, holds in rows:
            if last is not None and t != last:
                snapshot(last)
            last = t
            if pred in marks:
                (marks[pred].add if holds else marks[pred].discard)(a0)
            if pred in at_preds and a1 is not None:
                if holds:
                    where[a0] = a1
                elif where.get(a0) == a1:
                    del where[a0]
            if pred in alive_preds and a1 is None:
                alive[a0] = bool(holds)
            if pred in heading_preds and a1 is not None:
                if holds:
                    heading[a0] = a1
                elif heading.get(a0) == a1:
                    del heading[a0]
        if last is not None:
            snapshot(last)
        if not times or times[0] > 0:
            times.insert(0, 0)
            states.insert(0, BoardState(0, {}, []))
        return cls(board, episode, times, states, cells)

    @property
    def last_t(self) -> int:
        return self.times[-1]

    def at(self, t: int) -> BoardState:
        """The board at the end of timestep t."""
        i = bisect.bisect_right(self.times, t) - 1
        return self.states[max(i, 0)]

    def deaths(self) -> dict[int, list[str]]:
        """t -> the `alive` atoms (`alive(red-agent-1)`) of the pieces that died in t: the atoms whose
        why-trees the replay's step documents show."""
        out: dict[int, list[str]] = {}
        before: dict[str, bool] = {}
        for t, state in zip(self.times, self.states):
            for p in state.pieces:
                alive = self.board.pieces[p.kind].alive
                if alive and before.get(p.thing) and not p.alive:
                    out.setdefault(t, []).append(f"{alive}({p.thing})")
                before[p.thing] = p.alive
        return out

    def cell_of(self, node: str, t: int) -> tuple[int, int] | None:
        """(row, col) of a node at t: a cell itself, or the cell where a piece stands."""
        if node in self.cells:
            return self.cells[node]
        piece = next((p for p in self.at(t).pieces if p.thing == node), None)
        return None if piece is None else (piece.row, piece.col)


def piece_color(board: Board, thing: str) -> tuple[int, int, int] | None:
    """The colour `thing` is drawn in on the board (the first kind of pieces whose `colors` name it),
    or None: what its plots' lines take."""
    return next((c for k in board.pieces.values() if (c := k.color(thing)) is not None), None)


def _thing_kinds(con: RunConnection, board: Board) -> dict[str, str]:
    """Thing -> its pieces' kind: the things an atom of the kind's `things` predicate names."""
    out: dict[str, str] = {}
    for kind, spec in board.pieces.items():
        for (name,) in con.execute(
                "SELECT DISTINCT n.name FROM raw.atoms a JOIN raw.labels l ON l.label = a.label "
                "JOIN raw.nodes n ON n.node = a.arg0 WHERE l.name = ? AND a.arg1 < 0", [spec.things]).fetchall():
            out.setdefault(name, kind)
    return out


def _ordinal(name: str) -> tuple[Any, ...]:
    """red-agent-10 after red-agent-2."""
    return tuple(int(p) if p.isdigit() else p for p in name.split("-"))
