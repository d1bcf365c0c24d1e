"""The board: map (static), agents, bullets, each agent's action and the cells the step's rule firings
name, logged as columns (one `send_columns` per entity, rows only where something changed)."""
from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np
import rerun as rr
from tracelab.viewers.replay import style
from tracelab.viewers.replay.columns import send_per_entity

from tracelab.viewers.board import (
    NO_ACTION,
    NOTHING,
    PHASES,
    TEAMS,
    BoardMap,
    EpisodeBoard,
)

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


@lru_cache(maxsize=8)
def _static_map(width: int, height: int, image: bytes, bases: tuple[int, int, int, int]
                ) -> tuple[tuple[str, Any], ...]:
    """The static entities of a map, built once per map (an archetype converts its data to Arrow when it
    is made; logging it again into the next episode's recording is then cheap)."""
    m = BoardMap(width, height, np.zeros((0, 2), np.int64), np.array(bases, np.int64).reshape(2, 2))
    xs = np.arange(width + 1, dtype=np.float32)
    ys = np.arange(height + 1, dtype=np.float32)
    strips = [[(x, ys[0]), (x, ys[-1])] for x in xs] + [[(xs[0], y), (xs[-1], y)] for y in ys]
    base_cells = m.bases[:, 1] * width + m.bases[:, 0]
    terrain_image = np.frombuffer(image, dtype=np.uint8).reshape(height, width)
    return ((style.BOARD, style.annotation_context()),
            (style.TERRAIN, rr.SegmentationImage(terrain_image, draw_order=-10.0)),
            (style.GRID, rr.LineStrips2D(strips, radii=0.015, colors=(110, 110, 110), draw_order=0.0)),
            (style.BASES, rr.Boxes2D(centers=style.cell_centers(m, base_cells), half_sizes=(0.5, 0.5),
                                     class_ids=[style.RED_BASE, style.BLUE_BASE], radii=0.05,
                                     draw_order=1.0)))


def log_map(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    """The terrain (a segmentation image: free, mountain, bases), grid lines and base outlines, static;
    the annotation context for the classes."""
    m = board.map
    for path, archetype in _static_map(m.width, m.height, terrain(board).tobytes(),
                                       tuple(m.bases.ravel().tolist())):
        rec.log(path, archetype, static=True)


def _slot_times(slots: np.ndarray) -> list[rr.TimeColumn]:
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
    per_agent = [_changed(cell[:, i], alive[:, i], health[:, i], ammo[:, i]) for i in range(len(board.agents))]
    rows = np.concatenate(per_agent)
    agent = np.repeat(np.arange(len(board.agents)), [len(r) for r in per_agent])
    on = alive[rows, agent]
    names = [style.short_name(a) for a in board.agents]
    labels = [f"{names[i]} ♥{h:g} ⁍{a}" if live else f"{names[i]} dead"
              for i, live, h, a in zip(agent.tolist(), on.tolist(), health[rows, agent].round(2).tolist(),
                                       ammo[rows, agent].tolist())]
    send_per_entity(
        rec, [f"{style.AGENTS}/{a}" for a in board.agents], [len(r) for r in per_agent], _slot_times(rows),
        rr.Points2D.columns(
            positions=style.cell_centers(board.map, cell[rows, agent]),
            radii=np.where(on, 0.32, 0.18).astype(np.float32),
            class_ids=np.where(on, style.TEAM_AGENT_CLASS[board.agent_team[agent]], style.DEAD_AGENT),
            labels=labels, draw_order=np.full(len(rows), 10.0, dtype=np.float32)))


def log_bullets(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    """The bullets in flight, one arrow each pointing its way, one entity per team
    (/board/bullets/red), a row whenever one of the team's bullets moved, appeared or went."""
    n_slots = (board.steps + 1) * len(PHASES)
    cell = board.phase_bullet_cell.reshape(n_slots, -1)
    direction = board.phase_bullet_dir.reshape(n_slots, -1)
    paths, slots, per_row, cells, dirs, team_ids = [], [], [], [], [], []
    for team, name in enumerate(TEAMS):
        mine = board.bullet_team == team
        if not mine.any():
            continue
        c, d = cell[:, mine], direction[:, mine]
        rows = _changed(c, d)
        c, d = c[rows], d[rows]
        flying = c >= 0
        paths.append(f"{style.BULLETS}/{name}")
        slots.append(rows)
        per_row.append(flying.sum(axis=1))            # bullets in flight at each of the team's rows
        cells.append(c[flying])
        dirs.append(d[flying])
        team_ids.append(np.full(len(cells[-1]), team))
    if not paths:
        return
    c, d, team = np.concatenate(cells), np.concatenate(dirs), np.concatenate(team_ids)
    vec = style.DIRECTION_VECTORS[d] * 0.6
    columns = rr.Arrows2D.columns(
        origins=style.cell_centers(board.map, c) - vec / 2, vectors=vec,
        radii=np.full(len(vec), 0.07, dtype=np.float32), class_ids=style.TEAM_BULLET_CLASS[team],
        show_labels=np.zeros(len(vec), dtype=bool),
        draw_order=np.full(len(vec), 12.0, dtype=np.float32)).partition(np.concatenate(per_row))
    send_per_entity(rec, paths, [len(r) for r in slots], _slot_times(np.concatenate(slots)), columns)


def log_actions(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    """Each living agent's action of the step, at the step's first pass, one entity per team and kind:
    /board/actions/red/move holds an arrow from the cell each moving agent started on,
    /board/actions/red/shot a line along each shot."""
    steps = np.arange(1, board.steps + 1)
    both = np.concatenate([steps, steps])                   # red's rows, then blue's
    times = [rr.TimeColumn(style.STEP, sequence=both),
             rr.TimeColumn(style.PASS, sequence=style.pass_time(both, 0))]
    acted = board.alive[:-1] & (board.action[1:] != NO_ACTION) & (board.action[1:] != NOTHING)
    act = board.action[1:]
    origin = style.cell_centers(board.map, board.agent_cell[:-1])     # where each agent began step s
    moves, shots = [], []
    for team in range(len(TEAMS)):
        mine = board.agent_team == team
        a, o = act[:, mine], origin[:, mine]
        move, shot = acted[:, mine] & (a < 4), acted[:, mine] & (a >= 4)
        moves.append((o[move], style.DIRECTION_VECTORS[a[move] % 4] * 0.9, move.sum(axis=1), team))
        shots.append((o[shot], style.DIRECTION_VECTORS[a[shot] % 4] * 2.5, shot.sum(axis=1), team))
    colour = np.concatenate([np.repeat(style.TEAM_COLOR[t][None], len(o), 0) for o, _, _, t in moves])
    vec = np.concatenate([v for _, v, _, _ in moves])
    send_per_entity(rec, [f"{style.ACTIONS}/{name}/move" for name in TEAMS], [len(steps)] * 2, times,
                    rr.Arrows2D.columns(
                        origins=np.concatenate([o for o, _, _, _ in moves]), vectors=vec,
                        radii=np.full(len(vec), 0.05, dtype=np.float32), colors=colour,
                        draw_order=np.full(len(vec), 11.0, np.float32),
                    ).partition(np.concatenate([n for _, _, n, _ in moves])))
    origins = np.concatenate([o for o, _, _, _ in shots])
    strips = np.stack([origins, origins + np.concatenate([v for _, v, _, _ in shots])], axis=1)
    colour = np.concatenate([np.repeat(style.TEAM_COLOR[t][None], len(o), 0) for o, _, _, t in shots])
    send_per_entity(rec, [f"{style.ACTIONS}/{name}/shot" for name in TEAMS], [len(steps)] * 2, times,
                    rr.LineStrips2D.columns(
                        strips=strips, radii=np.full(len(strips), 0.035, dtype=np.float32),
                        colors=colour, draw_order=np.full(len(strips), 11.0, np.float32),
                    ).partition(np.concatenate([n for _, _, n, _ in shots])))


def _marked(board: EpisodeBoard) -> np.ndarray:
    """Indices of the firings that mark the board: a cell named, a board phase, an event's head."""
    f = board.firings
    event = np.array([h.partition("(")[0] in MARKED_HEADS for h in f.head], dtype=bool)
    return np.flatnonzero((f.cell >= 0) & np.isin(f.phase, _MARKED_PHASES) & event)


def _label(rules: dict[str, int]) -> str:
    names = sorted(rules, key=rules.__getitem__)
    more = len(names) - _MAX_RULES_PER_LABEL
    return "\n".join(names[:_MAX_RULES_PER_LABEL]) + (f"\n+{more}" if more > 0 else "")


def log_fired(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    """Per step and board phase, the cells the step's firings so far name, outlined and labelled with the
    rules (so the end of the step shows all of them)."""
    f = board.firings
    rows = _marked(board)
    by_step = np.searchsorted(f.step[rows], np.arange(board.steps + 2))
    n_ph = len(_MARKED_PHASES)
    steps = np.repeat(np.arange(board.steps + 1), n_ph)               # a row per step and board phase
    passes = steps * style.PASS_PER_STEP + np.tile(_MARKED_PHASES, board.steps + 1)
    counts = np.zeros(len(steps), dtype=np.int64)
    cells, labels = [], []
    for s in np.unique(f.step[rows]).tolist():                          # the steps that mark a cell
        step_rows = rows[by_step[s]:by_step[s + 1]].tolist()
        per_cell: dict[int, dict[str, int]] = {}
        k = 0
        for j, ph in enumerate(_MARKED_PHASES):
            while k < len(step_rows) and f.phase[step_rows[k]] <= ph:
                i = step_rows[k]
                per_cell.setdefault(int(f.cell[i]), {}).setdefault(
                    f.rule[i], _LABEL_PRIORITY[PHASES[f.phase[i]]])
                k += 1
            counts[s * n_ph + j] = len(per_cell)
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
