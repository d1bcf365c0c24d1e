"""The board of an episode in the replay, any run's with a `[board]` (tracelab.board; an older run's
without a spec: viewers/board_state.py), the same the TUI draws: the cells as the env's `rgb_array`
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
from tracelab.envs.declared.render import CELL
from tracelab.store.reader import RunConnection
from tracelab.viewers.board_state import BoardTrack, Piece

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
    """Each piece's entity, a row where it changed (an empty row where it left the board), as columns."""
    rows: dict[str, list[tuple[int, Piece | None]]] = {}
    for t, state in zip(track.times, track.states):
        now = {p.thing: p for p in state.pieces}
        for thing, seen in rows.items():
            if thing not in now and seen[-1][1] is not None:
                seen.append((t, None))
        for thing, p in now.items():
            seen = rows.setdefault(thing, [])
            if not seen or seen[-1][1] is None or _key(seen[-1][1]) != _key(p):
                seen.append((t, p))
    for thing, seen in rows.items():
        pieces = [p for _, p in seen if p is not None]
        lengths = [int(p is not None) for _, p in seen]
        times = [rr.TimeColumn(style.STEP, sequence=[t for t, _ in seen])]
        kind = next(p.kind for p in pieces)
        rgb = board.pieces[kind].color(thing) or (255, 255, 255)
        at = np.array([(p.col + 0.5, p.row + 0.5) for p in pieces], np.float32).reshape(-1, 2)
        n = len(pieces)
        if board.pieces[kind].heading:
            vec = np.array([ARROW_VECTORS.get(p.arrow, (0.0, 0.0)) for p in pieces], np.float32).reshape(-1, 2)
            columns = rr.Arrows2D.columns(origins=at - vec / 2, vectors=vec, radii=np.full(n, 0.07, np.float32),
                                          colors=np.tile(np.array(rgb, np.uint8), (n, 1)),
                                          draw_order=np.full(n, 12.0, np.float32))
        else:
            columns = rr.Points2D.columns(
                positions=at, radii=np.array([0.32 if p.alive else 0.18 for p in pieces], np.float32),
                colors=np.array([rgb if p.alive else DEAD for p in pieces], np.uint8).reshape(-1, 3),
                labels=[f"{piece_label(thing)}{'' if p.alive else ' dead'}" for p in pieces],
                show_labels=np.ones(n, bool), draw_order=np.full(n, 10.0, np.float32))
        rec.send_columns(_path(kind, thing), indexes=times, columns=columns.partition(lengths))


def _key(p: Piece) -> tuple[int, int, bool, str]:
    return p.row, p.col, p.alive, p.arrow


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
    """A row at each step that outlines cells, and an empty one at the step after (within the episode)."""
    fired = fired_cells(con, board, track)
    steps = sorted({*fired, *(t + 1 for t in fired if t + 1 <= track.last_t)})
    if not steps:
        return
    cells = [(r, c) for t in steps for r, c in fired.get(t, {})]
    labels = [_label(rules) for t in steps for rules in fired.get(t, {}).values()]
    n = len(cells)
    rec.send_columns(style.FIRED, indexes=[rr.TimeColumn(style.STEP, sequence=steps)],
                     columns=rr.Boxes2D.columns(
                         centers=np.array([(c + 0.5, r + 0.5) for r, c in cells], np.float32).reshape(-1, 2),
                         half_sizes=np.full((n, 2), 0.46, np.float32), labels=labels,
                         colors=np.tile(np.array(style.FIRED_COLOR, np.uint8), (n, 1)),
                         radii=np.full(n, 0.025, np.float32), draw_order=np.full(n, 5.0, np.float32),
                     ).partition([len(fired.get(t, {})) for t in steps]))
