"""The board: map (static), agents, bullets, each agent's action and the cells the step's rule firings
name, logged as columns (one `send_columns` per entity, rows only where something changed)."""
from __future__ import annotations

import numpy as np
import rerun as rr

from tracelab.store.board import NO_ACTION, NOTHING, PHASES, TEAMS, EpisodeBoard
from tracelab.viewers.replay import style

# phases whose firings mark the board (the snapshot and the shield's view change nothing on it)
_MARKED_PHASES = [i for i, name in enumerate(PHASES) if name not in ("start", "shield")]
# firings mark the board when their head is one of the game's events (the log keeps every firing): a
# bullet striking, a kill, a death, an unsafe or invalid action, a shot, a capture, an elimination
MARKED_HEADS = ("struck", "blanked", "caught", "killed", "alive", "unsafe", "invalid", "fired", "captured",
                "eliminated")
# which rules a crowded cell's label lists first
_LABEL_PRIORITY = {name: rank for rank, name in enumerate(("end", "deaths", "hits", "walk-in", "bullets",
                                                            "act"))}
_MAX_RULES_PER_LABEL = 3


def terrain(board: EpisodeBoard) -> np.ndarray:
    """[height, width] class ids of the map as drawn (row 0 is the top row, the game's y = height - 1)."""
    m = board.map
    image = np.full((m.height, m.width), style.FREE, dtype=np.uint8)
    image[m.height - 1 - m.mountains[:, 1], m.mountains[:, 0]] = style.MOUNTAIN
    for team in (0, 1):
        x, y = m.bases[team]
        image[m.height - 1 - y, x] = style.RED_BASE + team
    return image


def log_map(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    """The terrain (a segmentation image: free, mountain, bases), grid lines and base outlines, static;
    the annotation context for the classes."""
    m = board.map
    rec.log(style.BOARD, style.annotation_context(), static=True)
    rec.log(style.TERRAIN, rr.SegmentationImage(terrain(board), draw_order=-10.0), static=True)
    xs = np.arange(m.width + 1, dtype=np.float32)
    ys = np.arange(m.height + 1, dtype=np.float32)
    strips = [[(x, ys[0]), (x, ys[-1])] for x in xs] + [[(xs[0], y), (xs[-1], y)] for y in ys]
    rec.log(style.GRID, rr.LineStrips2D(strips, radii=0.015, colors=(110, 110, 110), draw_order=0.0),
            static=True)
    for team, name in enumerate(("red", "blue")):
        x, y = m.bases[team]
        rec.log(f"{style.BASES}/{name}", rr.Boxes2D(
            centers=style.cell_centers(m, np.array([y * m.width + x])), half_sizes=(0.5, 0.5),
            class_ids=style.RED_BASE + team, radii=0.05, draw_order=1.0), static=True)


def _slot_times(board: EpisodeBoard, slots: np.ndarray) -> list[rr.TimeColumn]:
    n_ph = len(PHASES)
    step = slots // n_ph
    return [rr.TimeColumn(style.STEP, sequence=step),
            rr.TimeColumn(style.PASS, sequence=style.pass_time(step, slots % n_ph))]


def _changed(*arrays: np.ndarray) -> np.ndarray:
    """Rows of [slots, ...] arrays where any differs from the row before (the first row always)."""
    keep = np.zeros(len(arrays[0]), dtype=bool)
    keep[0] = True
    for a in arrays:
        diff = a[1:] != a[:-1]
        keep[1:] |= diff.reshape(len(diff), -1).any(axis=1)
    return np.flatnonzero(keep)


def log_agents(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    """One point per agent, coloured by team (grey when dead), labelled with health and ammo."""
    n_slots = (board.steps + 1) * len(PHASES)
    cell = board.phase_agent_cell.reshape(n_slots, -1)
    alive = board.phase_alive.reshape(n_slots, -1)
    health = board.phase_health.reshape(n_slots, -1)
    ammo = board.phase_ammo.reshape(n_slots, -1)
    for i, agent in enumerate(board.agents):
        rows = _changed(cell[:, i], alive[:, i], health[:, i], ammo[:, i])
        on = alive[rows, i]
        name = style.short_name(agent)
        labels = [f"{name} ♥{h:g} ⁍{a}" if live else f"{name} dead"
                  for live, h, a in zip(on.tolist(), health[rows, i].round(2).tolist(), ammo[rows, i].tolist())]
        rec.send_columns(
            f"{style.AGENTS}/{agent}", indexes=_slot_times(board, rows),
            columns=rr.Points2D.columns(
                positions=style.cell_centers(board.map, cell[rows, i]),
                radii=np.where(on, 0.32, 0.18).astype(np.float32),
                class_ids=np.where(on, style.TEAM_AGENT_CLASS[board.agent_team[i]], style.DEAD_AGENT),
                labels=labels, draw_order=np.full(len(rows), 10.0, dtype=np.float32)))


def log_bullets(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    """The bullets in flight, one arrow each pointing its way, one entity per team
    (/board/bullets/red), a row whenever one of the team's bullets moved, appeared or went."""
    n_slots = (board.steps + 1) * len(PHASES)
    cell = board.phase_bullet_cell.reshape(n_slots, -1)
    direction = board.phase_bullet_dir.reshape(n_slots, -1)
    for team, name in enumerate(TEAMS):
        mine = board.bullet_team == team
        if not mine.any():
            continue
        c, d = cell[:, mine], direction[:, mine]
        rows = _changed(c, d)
        c, d = c[rows], d[rows]
        flying = c >= 0
        vec = style.DIRECTION_VECTORS[d[flying]] * 0.6
        rec.send_columns(
            f"{style.BULLETS}/{name}", indexes=_slot_times(board, rows),
            columns=rr.Arrows2D.columns(
                origins=style.cell_centers(board.map, c[flying]) - vec / 2, vectors=vec,
                radii=np.full(len(vec), 0.07, dtype=np.float32),
                class_ids=np.full(len(vec), style.TEAM_BULLET_CLASS[team]),
                show_labels=np.zeros(len(vec), dtype=bool),
                draw_order=np.full(len(vec), 12.0, dtype=np.float32)).partition(flying.sum(axis=1)))


def log_actions(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    """Each living agent's action of the step, at the step's first pass, one entity per team and kind:
    /board/actions/red/move holds an arrow from the cell each moving agent started on,
    /board/actions/red/shot a line along each shot."""
    steps = np.arange(1, board.steps + 1)
    times = [rr.TimeColumn(style.STEP, sequence=steps),
             rr.TimeColumn(style.PASS, sequence=style.pass_time(steps, 0))]
    acted = board.alive[:-1] & (board.action[1:] != NO_ACTION) & (board.action[1:] != NOTHING)
    act = board.action[1:]
    origin = style.cell_centers(board.map, board.agent_cell[:-1])     # where each agent began step s
    for team, name in enumerate(TEAMS):
        mine = board.agent_team == team
        colour = style.TEAM_COLOR[team]
        a, o = act[:, mine], origin[:, mine]
        move, shot = acted[:, mine] & (a < 4), acted[:, mine] & (a >= 4)
        vec = style.DIRECTION_VECTORS[a[move] % 4] * 0.9
        rec.send_columns(f"{style.ACTIONS}/{name}/move", indexes=times, columns=rr.Arrows2D.columns(
            origins=o[move], vectors=vec, radii=np.full(len(vec), 0.05, dtype=np.float32),
            colors=np.repeat(colour[None], len(vec), 0), draw_order=np.full(len(vec), 11.0, np.float32),
            ).partition(move.sum(axis=1)))
        strips = np.stack([o[shot], o[shot] + style.DIRECTION_VECTORS[a[shot] % 4] * 2.5], axis=1)
        rec.send_columns(f"{style.ACTIONS}/{name}/shot", indexes=times, columns=rr.LineStrips2D.columns(
            strips=list(strips), radii=np.full(len(strips), 0.035, dtype=np.float32),
            colors=np.repeat(colour[None], len(strips), 0),
            draw_order=np.full(len(strips), 11.0, np.float32)).partition(shot.sum(axis=1)))


def _marked(board: EpisodeBoard) -> np.ndarray:
    """Indices of the firings that mark the board: a cell named, a board phase, an event's head."""
    f = board.firings
    event = np.array([h.partition("(")[0] in MARKED_HEADS for h in f.head], dtype=bool)
    return np.flatnonzero((f.cell >= 0) & np.isin(f.phase, _MARKED_PHASES) & event)


def _label(rules: dict[str, int]) -> str:
    names = sorted(rules, key=rules.__getitem__)
    more = len(names) - _MAX_RULES_PER_LABEL
    return "\n".join(names[:_MAX_RULES_PER_LABEL]) + (f"\n+{more}" if more > 0 else "")


def fired_cells(board: EpisodeBoard, step: int, upto_phase: int = len(PHASES) - 1
                ) -> tuple[list[int], list[str]]:
    """The cells the firings of `step` up to `upto_phase` name (board phases only), each with a label
    listing its rules (the later phases' first, at most _MAX_RULES_PER_LABEL, then '+n')."""
    f = board.firings
    rows = _marked(board)
    rows = rows[(f.step[rows] == step) & (f.phase[rows] <= upto_phase)]
    per_cell: dict[int, dict[str, int]] = {}
    for i in rows.tolist():
        per_cell.setdefault(int(f.cell[i]), {}).setdefault(f.rule[i], _LABEL_PRIORITY[PHASES[f.phase[i]]])
    cells = sorted(per_cell)
    return cells, [_label(per_cell[c]) for c in cells]


def log_fired(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    """Per step and board phase, the cells the step's firings so far name, outlined and labelled with the
    rules (so the end of the step shows all of them)."""
    f = board.firings
    rows = _marked(board)
    by_step = np.searchsorted(f.step[rows], np.arange(board.steps + 2))
    steps, passes, counts, cells, labels = [], [], [], [], []
    for s in range(board.steps + 1):
        step_rows = rows[by_step[s]:by_step[s + 1]].tolist()
        per_cell: dict[int, dict[str, int]] = {}
        k = 0
        for ph in _MARKED_PHASES:
            while k < len(step_rows) and f.phase[step_rows[k]] <= ph:
                i = step_rows[k]
                per_cell.setdefault(int(f.cell[i]), {}).setdefault(
                    f.rule[i], _LABEL_PRIORITY[PHASES[f.phase[i]]])
                k += 1
            steps.append(s)
            passes.append(s * style.PASS_PER_STEP + ph)
            counts.append(len(per_cell))
            for c in sorted(per_cell):
                cells.append(c)
                labels.append(_label(per_cell[c]))
    centers = style.cell_centers(board.map, np.array(cells, dtype=np.int64))
    rec.send_columns(style.FIRED, indexes=[rr.TimeColumn(style.STEP, sequence=steps),
                                           rr.TimeColumn(style.PASS, sequence=passes)],
                     columns=rr.Boxes2D.columns(
                         centers=centers, half_sizes=np.full((len(cells), 2), 0.46, np.float32),
                         class_ids=np.full(len(cells), style.FIRED_CELL), labels=labels,
                         radii=np.full(len(cells), 0.025, np.float32),
                         draw_order=np.full(len(cells), 5.0, np.float32)).partition(counts))


def log_board(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    log_map(rec, board)
    log_agents(rec, board)
    log_bullets(rec, board)
    log_actions(rec, board)
    log_fired(rec, board)
