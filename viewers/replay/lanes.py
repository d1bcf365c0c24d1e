"""State lanes (rerun's StateChange, /lanes/PRED/THING): for each predicate `--lanes` names and each thing
an atom of it is about (its first argument), the atom's state at the end of each step where it changed:
a binary predicate's second argument where it holds (`atLoc(red-agent-1, c3_4)`: `c3_4`; a run's cell ids
with their (x, y)), a unary one's `true`, `false` or its bound. Any run's predicates, a game's or a
reasoning's; and `action`, each agent's action in each step (the run's `steps` rows)."""
from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np
import rerun as rr
from tracelab.viewers.replay import style
from tracelab.viewers.replay.columns import send_per_entity
from tracelab.viewers.replay.plots import StepRow

from tracelab.engine.terminal_text import printable
from tracelab.store.coordinates import run_grid
from tracelab.store.names import unknown_name_message
from tracelab.store.reader import RunConnection

# `--lanes`' default: the ones of these the run has (a run of another world may have none of them)
DEFAULT_LANES = ("alive", "atLoc", "health", "ammo", "action")
MAX_LANES = 200     # lanes drawn (a predicate over every cell of a big board would make thousands)
NOTHING = "-"       # a binary predicate that holds for no second argument
ACTION = "action"   # the lane of the agents' actions (a predicate of that name is drawn instead)


def parse_lanes(text: str) -> tuple[str, ...]:
    """'alive,ammo' -> ('alive', 'ammo')."""
    return tuple(x.strip() for x in text.split(",") if x.strip())


def check_lanes(con: RunConnection, lanes: tuple[str, ...]) -> tuple[str, ...]:
    """The lanes the run can draw: `lanes` when every one is a predicate of the run (else a ValueError
    naming its predicates), the default's that are when `lanes` is the default."""
    names = [n for (n,) in con.execute("SELECT name FROM raw.labels WHERE arity IN (1, 2) ORDER BY name").fetchall()]
    if con.execute("SELECT EXISTS (SELECT 1 FROM steps)").fetchall()[0][0]:
        names.append(ACTION)
    if lanes == DEFAULT_LANES:
        return tuple(lane for lane in lanes if lane in names)
    for lane in lanes:
        if lane not in names:
            raise ValueError(unknown_name_message("predicate", lane, names, where=" in this run (--lanes)"))
    return lanes


def _state(lower: float, upper: float) -> str:
    return "true" if lower >= 1 else "false" if upper <= 0 else f"[{lower:g},{upper:g}]"


def lane_rows(con: RunConnection, episode: int, lanes: tuple[str, ...], steps: Sequence[StepRow] = (),
              agents: set[str] | None = None) -> dict[tuple[str, str], list[tuple[int, str]]]:
    """(predicate, thing) -> [(t, its state at the end of t)] at each t where the state changed (one query),
    for at most MAX_LANES lanes; `action`'s from the episode's `steps` rows. `agents` (the default lanes
    of a game): only these things, not every bullet or cell an atom of the predicate is about."""
    if not lanes:
        return {}
    actions: dict[tuple[str, str], list[tuple[int, str]]] = {}
    if ACTION in lanes and not con.execute("SELECT EXISTS (SELECT 1 FROM raw.labels WHERE name = ?)",
                                           [ACTION]).fetchall()[0][0]:
        for t, agent, _, action in steps:
            actions.setdefault((ACTION, agent), []).append((t, action))
    grid = run_grid(con)
    rows = con.execute(
        "SELECT c.t, l.name, n0.name, n1.name, c.new_lower, c.new_upper FROM raw.changes c "
        "JOIN raw.atoms a ON a.atom = c.atom JOIN raw.labels l ON l.label = a.label "
        "JOIN raw.nodes n0 ON n0.node = a.arg0 LEFT JOIN raw.nodes n1 ON n1.node = a.arg1 "
        "WHERE c.episode = ? AND l.name IN (SELECT unnest(?::VARCHAR[])) ORDER BY c.seq",
        [episode, list(lanes)]).fetchall()
    held: dict[tuple[str, str], dict[str, None]] = {}     # a binary lane's second arguments that hold, in order
    now: dict[tuple[str, str], str] = {}
    out: dict[tuple[str, str], list[tuple[int, str]]] = {}

    def close(t: int) -> None:
        for key, state in now.items():
            seen = out.setdefault(key, [])
            if not seen or seen[-1][1] != state:
                seen.append((t, state))

    last = None
    for t, pred, thing, second, lower, upper in rows:
        if last is not None and t != last:
            close(last)
        last = t
        key = (pred, thing)
        if agents is not None and thing not in agents:
            continue
        if key not in now and len(now) >= MAX_LANES:
            continue
        if second is None:
            now[key] = _state(lower, upper)
            continue
        args = held.setdefault(key, {})
        if lower >= 1:
            args[grid.node_text(second) if grid else second] = None
        else:
            args.pop(grid.node_text(second) if grid else second, None)
        now[key] = ", ".join(args) or NOTHING
    if last is not None:
        close(last)
    order = {p: i for i, p in enumerate(lanes)}
    return dict(sorted({**out, **actions}.items(), key=lambda kv: (order[kv[0][0]], kv[0][1])))


@lru_cache(maxsize=1)
def _truth_states() -> rr.StateConfiguration:
    """A unary lane's colours, built once."""
    return rr.StateConfiguration(values=["true", "false"], colors=[0x4CAF50FF, 0x808080FF])


def log_lanes(rec: rr.RecordingStream, con: RunConnection, episode: int, lanes: tuple[str, ...],
              steps: Sequence[StepRow] = (), agents: set[str] | None = None) -> int:
    """The episode's lanes (only `agents`' when given), a row where a state changed (an action at each
    step); returns how many lanes were drawn."""
    rows = lane_rows(con, episode, lanes, steps, agents)
    if not rows:
        return 0
    paths = [f"{style.LANES}/{rr.escape_entity_path_part(p)}/{rr.escape_entity_path_part(thing)}"
             for p, thing in rows]
    steps = np.array([t for seen in rows.values() for t, _ in seen], np.int64)
    send_per_entity(rec, paths, [len(seen) for seen in rows.values()], [rr.TimeColumn(style.STEP, sequence=steps)],
                    rr.StateChange.columns(state=[printable(s) for seen in rows.values() for _, s in seen]))
    for path, seen in zip(paths, rows.values()):
        if {s for _, s in seen} <= {"true", "false"}:
            rec.log(path, _truth_states(), static=True)
    return len(rows)
