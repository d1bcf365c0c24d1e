"""The board of an episode in the replay, any run's with a `[board]` (tracelab.board; a RuleSim GridWar
run's is war.toml's: viewers/board_state.py), the same the TUI draws: the cells as the env's `rgb_array`
paints them (tracelab.envs.declared.render), a frame at t = 0 and wherever a mark moved; each piece
(/board/agents/red-agent-1) a point in its colour labelled with its name (grey and small when dead) or an
arrow the way it heads (a bullet), logged where it changed; and at each step the cells where a rule set
an atom of an `annotate` predicate, outlined and labelled with the rules (/board/fired).

Board space: one unit a cell, x to the right, y down, cell (row, col) centred on (col + 0.5, row + 0.5);
the image is scaled to it."""
from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from tracelab.viewers.replay import style

from tracelab.board import Board, piece_label
from tracelab.envs.declared.render import DeclaredPainter
from tracelab.envs.render_rgb import CELL
from tracelab.store.reader import RunConnection
from tracelab.viewers.board_state import BoardTrack

MAX_IMAGE_SIDE = 1536  # pixels: a big board's cells are drawn smaller (a frame of 256 x 24 px a side is 113 MB)
MAX_RULES_PER_LABEL = 3
DEAD = (140, 140, 140)
ARROW_VECTORS = {"↑": (0.0, -0.6), "↓": (0.0, 0.6), "←": (-0.6, 0.0), "→": (0.6, 0.0)}
MARGIN = 0.2          # cells around the board in the view's bounds
LABEL_ROOM = 0.5      # cells under the bottom row: a piece there has its label under it


def painter(board: Board) -> DeclaredPainter:
    return DeclaredPainter(board, max(2, min(CELL, MAX_IMAGE_SIDE // max(board.height, board.width))))


def visual_bounds(board: Board) -> rrb.VisualBounds2D:
    """The whole board with a margin (the right edge included), and room for a label under it."""
    return rrb.VisualBounds2D(x_range=[-MARGIN, board.width + MARGIN],
                                       y_range=[-MARGIN, board.height + LABEL_ROOM])


def log_board(rec: rr.RecordingStream, con: RunConnection, board: Board, episode: int,
              track: BoardTrack | None = None) -> BoardTrack:
    """Log the episode's board into `rec`; returns its track (what was drawn)."""
    track = track or BoardTrack.read(con, board, episode)
    draw = painter(board)
    rec.log(style.TERRAIN, rr.Transform3D(scale=1.0 / draw.cell), static=True)
    if board.marks:
        last = None
        for t, state in zip(track.times, track.states):
            if state.marked != last:
                rec.set_time(style.STEP, sequence=t)
                rec.log(style.TERRAIN, rr.Image(draw(state.marked, board.mark_colors), draw_order=-10.0))
                last = state.marked
    else:
        rec.log(style.TERRAIN, rr.Image(draw.background, draw_order=-10.0), static=True)
    _log_pieces(rec, board, track)
    _log_fired(rec, con, board, track)
    return track


def _log_pieces(rec: rr.RecordingStream, board: Board, track: BoardTrack) -> None:
    shown: dict[str, tuple] = {}
    for t, state in zip(track.times, track.states):
        now = {p.thing: p for p in state.pieces}
        for thing in [x for x in shown if x not in now]:          # left the board (a bullet's end)
            rec.set_time(style.STEP, sequence=t)
            rec.log(_path(shown.pop(thing)[0], thing), rr.Clear(recursive=False))
        for thing, p in now.items():
            key = (p.kind, p.row, p.col, p.alive, p.arrow)
            if shown.get(thing) == key:
                continue
            shown[thing] = key
            rec.set_time(style.STEP, sequence=t)
            rgb = board.pieces[p.kind].color(thing) or (255, 255, 255)
            at = (p.col + 0.5, p.row + 0.5)
            if p.arrow:
                dx, dy = ARROW_VECTORS[p.arrow]
                rec.log(_path(p.kind, thing), rr.Arrows2D(origins=[(at[0] - dx / 2, at[1] - dy / 2)],
                                                          vectors=[(dx, dy)], radii=0.07, colors=[rgb],
                                                          draw_order=12.0))
            else:
                label = f"{piece_label(thing)}{'' if p.alive else ' dead'}"
                rec.log(_path(p.kind, thing), rr.Points2D([at], radii=0.32 if p.alive else 0.18,
                                                          colors=[rgb if p.alive else DEAD], labels=[label],
                                                          show_labels=True, draw_order=10.0))


def _path(kind: str, thing: str) -> str:
    return f"{style.BOARD}/{kind}/{thing}"


def fired_cells(con: RunConnection, board: Board, track: BoardTrack) -> dict[int, dict[tuple[int, int], list[str]]]:
    """t -> cell (row, col) -> the rules that set an atom of an `annotate` predicate there in that step
    (not the delayed rules that carry the last step over: pass 0): on the cell the atom names, else where
    the piece it names stands, else the first piece the firing's bindings name."""
    if not board.annotate:
        return {}
    rows = con.execute(
        "SELECT c.t, r.name, n0.name, n1.name, g.var_values FROM raw.changes c "
        "JOIN raw.atoms a ON a.atom = c.atom JOIN raw.labels l ON l.label = a.label "
        "JOIN raw.rules r ON r.rule = c.cause_id LEFT JOIN raw.nodes n0 ON n0.node = a.arg0 "
        "LEFT JOIN raw.nodes n1 ON n1.node = a.arg1 LEFT JOIN raw.groundings g ON g.grounding = c.grounding "
        "WHERE c.episode = ? AND c.cause_kind = 2 AND c.pass_no > 0 AND l.name IN (SELECT unnest(?::VARCHAR[])) "
        "ORDER BY c.seq", [track.episode, list(board.annotate)]).fetchall()
    nodes: dict[int, str] = {}
    wanted = sorted({v for *_, values in rows for v in (values or [])})
    if wanted:
        nodes = dict(con.execute("SELECT node, name FROM raw.nodes WHERE node IN (SELECT unnest(?::BIGINT[]))",
                                 [wanted]).fetchall())
    out: dict[int, dict[tuple[int, int], list[str]]] = {}
    for t, rule, a0, a1, values in rows:
        names = [a0, a1, *(nodes.get(v) for v in (values or []))]
        cell = next((c for n in names if n is not None and (c := track.cell_of(n, t)) is not None), None)
        if cell is not None:
            rules = out.setdefault(int(t), {}).setdefault(cell, [])
            if rule not in rules:
                rules.append(rule)
    return out


def _label(rules: list[str]) -> str:
    more = len(rules) - MAX_RULES_PER_LABEL
    return "\n".join(rules[:MAX_RULES_PER_LABEL]) + (f"\n+{more}" if more > 0 else "")


def _log_fired(rec: rr.RecordingStream, con: RunConnection, board: Board, track: BoardTrack) -> None:
    fired = fired_cells(con, board, track)
    for t in range(track.last_t + 2):                 # each step's outlines go at the next step
        cells = fired.get(t)
        if cells is None and t - 1 not in fired:
            continue
        rec.set_time(style.STEP, sequence=t)
        cells = cells or {}
        centers = np.array([(c + 0.5, r + 0.5) for r, c in cells], np.float32).reshape(-1, 2)
        rec.log(style.FIRED, rr.Boxes2D(centers=centers, half_sizes=np.full((len(cells), 2), 0.46, np.float32),
                                        labels=[_label(v) for v in cells.values()], colors=[style.FIRED_COLOR],
                                        radii=0.025, draw_order=5.0))
