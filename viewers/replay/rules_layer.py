"""The rules' side of a replay: every firing as a TextLog line (its level is the phase, so the log view
filters by phase), state lanes of selected labels, and a markdown why-document per step."""
from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

import numpy as np
import rerun as rr
from tracelab.viewers.replay import style
from tracelab.viewers.replay.columns import send_per_entity

from tracelab.viewers.board import PHASES, TEAMS, EpisodeBoard
from tracelab.store.episode import EpisodeTrace
from tracelab.store.model import RunModel
from tracelab.store.names import unknown_name_message
from tracelab.store.reader import RunConnection
from tracelab.store.coordinates import run_grid
from tracelab.store.why import explain_in, render_why
from tracelab.engine.terminal_text import printable
from tracelab.viewers.replay.markdown_text import code_block, literal

LANE_LABELS = ("alive", "atLoc", "health", "ammo", "action")
END_LABELS = ("captured", "eliminated")


def _bound(lo: np.ndarray, hi: np.ndarray) -> list[str]:
    """'[lo,hi]' of each pair; a game has a handful of distinct bounds, each formatted once."""
    pairs, which = np.unique(np.stack([lo, hi], axis=1), axis=0, return_inverse=True)
    texts = [f"[{a:g},{b:g}]" for a, b in pairs.tolist()]
    return [texts[i] for i in which.ravel().tolist()]


def firing_lines(board: EpisodeBoard) -> list[str]:
    """One line per firing: rule, bindings, head atom, old bound -> new bound."""
    f = board.firings
    old, new = _bound(f.old[:, 0], f.old[:, 1]), _bound(f.new[:, 0], f.new[:, 1])
    return [f"{r}({b}): {h} {o} -> {n}" for r, b, h, o, n in zip(f.rule, f.bindings, f.head, old, new)]


def log_rule_log(rec: rr.RecordingStream, board: EpisodeBoard) -> None:
    f = board.firings
    if not len(f):
        return
    colours = np.array([style.LOG_COLOR[p] for p in PHASES], dtype=np.uint8)
    rec.send_columns(style.RULE_LOG,
                     indexes=[rr.TimeColumn(style.STEP, sequence=f.step),
                              rr.TimeColumn(style.PASS, sequence=style.pass_time(f.step, f.phase))],
                     columns=rr.TextLog.columns(text=[printable(line) for line in firing_lines(board)],
                                                level=np.array(PHASES, dtype=object)[f.phase].tolist(),
                                                color=colours[f.phase]))


def parse_lanes(text: str) -> tuple[str, ...]:
    """'alive,ammo' -> ('alive', 'ammo'); an unknown lane is a ValueError naming the known ones."""
    lanes = tuple(x.strip() for x in text.split(",") if x.strip())
    for lane in lanes:
        if lane not in LANE_LABELS:
            raise ValueError(unknown_name_message("lane", lane, LANE_LABELS, where=""))
    return lanes


def lane_values(board: EpisodeBoard, label: str) -> np.ndarray:
    """[steps + 1, agents] state text of one lane at the end of each step."""
    if label == "alive":
        return np.where(board.alive, "alive", "dead")
    if label == "atLoc":
        x, y = board.agent_x, board.agent_y
        return np.char.add(np.char.add(np.char.add("(", x.astype(str)), np.char.add(",", y.astype(str))), ")")
    if label == "health":
        return board.health.round(2).astype(str)
    if label == "ammo":
        return board.ammo.astype(str)
    if label == "action":
        names = np.array(("-",) + style.ACTION_LANE_TEXT, dtype=object)
        return names[board.action + 1].astype(str)
    raise ValueError(f"no lane {label!r}; lanes: {', '.join(LANE_LABELS)}")


@lru_cache(maxsize=1)
def _alive_states() -> rr.StateConfiguration:
    """The alive lane's colours, built once."""
    return rr.StateConfiguration(values=["alive", "dead"], colors=[0x4CAF50FF, 0x808080FF])


def log_lanes(rec: rr.RecordingStream, board: EpisodeBoard, labels: tuple[str, ...] = LANE_LABELS) -> None:
    """rerun state lanes (StateChange), one per label and agent, a row where the value changes."""
    last_pass = len(PHASES) - 1
    paths, counts, steps, states = [], [], [], []
    for label in labels:
        values = lane_values(board, label)
        for i, agent in enumerate(board.agents):
            v = values[:, i]
            rows = np.flatnonzero(np.r_[True, v[1:] != v[:-1]])
            paths.append(f"{style.LANES}/{label}/{agent}")
            counts.append(len(rows))
            steps.append(rows)
            states += v[rows].tolist()
    step = np.concatenate(steps) if steps else np.zeros(0, np.int64)
    send_per_entity(rec, paths, counts,
                    [rr.TimeColumn(style.STEP, sequence=step),
                     rr.TimeColumn(style.PASS, sequence=style.pass_time(step, last_pass))],
                    rr.StateChange.columns(state=states))
    if "alive" in labels:
        for agent in board.agents:
            rec.log(f"{style.LANES}/alive/{agent}", _alive_states(), static=True)


def explained_atoms(board: EpisodeBoard) -> dict[int, list[str]]:
    """Per step, the atoms whose why-tree the step's document shows: alive(A) of each agent that died in
    it, and at the last step the game's end (captured(T), eliminated(T))."""
    out: dict[int, list[str]] = {}
    died = board.alive[:-1] & ~board.alive[1:]
    for s, i in zip(*np.nonzero(died)):
        out.setdefault(int(s) + 1, []).append(f"alive({board.agents[i]})")
    f = board.firings
    for i in f.at(board.steps).tolist():
        label = f.head[i].partition("(")[0]
        if label in END_LABELS and f.new[i, 0] >= 1.0 and f.head[i] not in out.get(board.steps, []):
            out.setdefault(board.steps, []).append(f.head[i])
    return out


def _step_header(board: EpisodeBoard, s: int, rewards: np.ndarray | None) -> list[str]:
    lines = [f"## Episode {board.episode}, step {s} of {board.steps}"]
    if s == board.steps and board.outcome:
        lines.append(f"**End of the game: {literal(board.outcome)} for red.**\n")
    if s > 0:
        acts = ", ".join(f"{literal(style.short_name(a))} {style.ACTION_NAMES[act] if act >= 0 else '-'}"
                         for a, act, live in zip(board.agents, board.action[s].tolist(),
                                                 board.alive[s - 1].tolist()) if live)
        lines.append(f"- actions: {acts or 'none (no agent alive)'}")
    if rewards is not None and s > 0:
        lines.append("- reward: " + ", ".join(f"{team} {rewards[s, t]:g}" for t, team in enumerate(TEAMS)))
    return lines


def why_documents(con: RunConnection, board: EpisodeBoard, rewards: np.ndarray | None = None,
                  depth: int = 6, model: Callable[[], RunModel] | None = None) -> list[str]:
    """A markdown document per step: what happened, and the why-trees (as `tracelab why` prints them)
    of the step's deaths and of the game's end. `model` gives the run's model (read only if needed)."""
    wanted = explained_atoms(board)
    if wanted:
        run_model = model() if model else RunModel(con)
        trace = EpisodeTrace(con, board.episode, columns=board.changes)
        run_model.prefetch_groundings(np.unique(trace.c["grounding"]))
    grid = run_grid(con)     # the cells' (x, y) beside their ids, as `tracelab why` shows them
    docs = []
    for s in range(board.steps + 1):
        lines = _step_header(board, s, rewards)
        atoms = wanted.get(s, [])
        if not atoms:
            lines.append("\nNo death and no end of game in this step.")
        for atom in atoms:
            tree = render_why(explain_in(run_model, trace, atom, s, depth), s, grid)
            lines += [f"\n### Why {literal(atom)}", *code_block(tree)]
        docs.append("\n".join(lines))
    return docs


def log_why(rec: rr.RecordingStream, con: RunConnection, board: EpisodeBoard,
            rewards: np.ndarray | None = None, depth: int = 6,
            model: Callable[[], RunModel] | None = None) -> None:
    docs = why_documents(con, board, rewards, depth, model)
    steps = np.arange(board.steps + 1)
    rec.send_columns(style.WHY, indexes=[rr.TimeColumn(style.STEP, sequence=steps),
                                         rr.TimeColumn(style.PASS, sequence=style.pass_time(steps, 0))],
                     columns=rr.TextDocument.columns(text=[printable(d, keep="\n\t") for d in docs],
                                                     media_type=["text/markdown"] * len(docs)))
