"""The board of a spec world's episode in the replay (a run whose config records the spec's `[board]`:
`tracelab play --env`, a training's evaluation games): the image the env's `rgb_array` draws
(tracelab.envs.declared.render), a frame at t = 0 and at each timestep where a mark moved, read from the
run's changes of the marks' predicates. The same board the TUI draws (tracelab.board)."""
from __future__ import annotations

from itertools import groupby

import rerun as rr
from tracelab.viewers.replay import style

from tracelab.board import Board
from tracelab.envs.declared.render import DeclaredPainter
from tracelab.envs.declared.render import CELL
from tracelab.store.reader import RunConnection

MAX_IMAGE_SIDE = 1536  # pixels: a big board's cells are drawn smaller (a frame of 256 x 24 px a side is 113 MB)


def painter(board: Board) -> DeclaredPainter:
    return DeclaredPainter(board, max(2, min(CELL, MAX_IMAGE_SIDE // max(board.height, board.width))))


def mark_frames(con: RunConnection, board: Board, episode: int, steps: int) -> list[tuple[int, dict[str, str]]]:
    """(t, cell -> the mark predicate true there at the end of t) for t = 0 and each t at which a mark's
    atom changed, up to t = steps - 1; the last predicate listed in `marks` wins a cell, as the env draws."""
    preds = list(board.marks)
    rows = con.execute(
        "SELECT c.t, l.name, n.name, c.new_lower = 1 AND c.new_upper = 1 FROM raw.changes c "
        "JOIN raw.atoms a ON a.atom = c.atom JOIN raw.labels l ON l.label = a.label "
        "JOIN raw.nodes n ON n.node = a.arg0 WHERE c.episode = ? AND a.arg1 < 0 AND c.t < ? "
        "AND l.name IN (SELECT unnest(?::VARCHAR[])) ORDER BY c.seq", [episode, steps, preds]).fetchall()
    true: dict[str, set[str]] = {p: set() for p in preds}
    frames: list[tuple[int, dict[str, str]]] = []
    for t, changes in groupby(rows, key=lambda r: int(r[0])):
        if not frames and t > 0:
            frames.append((0, {}))
        for _, pred, cell, holds in changes:
            (true[pred].add if holds else true[pred].discard)(cell)
        frames.append((t, {cell: p for p in preds for cell in sorted(true[p])}))
    return frames or [(0, {})]


def log_board(rec: rr.RecordingStream, con: RunConnection, board: Board, episode: int, steps: int) -> None:
    draw = painter(board)
    for t, marked in mark_frames(con, board, episode, steps):
        rec.set_time(style.STEP, sequence=t)
        rec.log(style.BOARD, rr.Image(draw(marked, board.mark_colors)))
