"""Plots: each agent's reward and return per step of an episode (from the run's `steps` rows), in its
piece's colour when it is one of the board's. A training's curves are not drawn: rerun plots a view on
the time panel's timeline only, and on the episode's `step` a panel of them stood empty; they are in
`tracelab tui RUN`'s Training view and `tracelab show`."""
from __future__ import annotations

from functools import cache

import numpy as np
import rerun as rr
from tracelab.viewers.replay import style
from tracelab.viewers.replay.columns import send_per_entity
from tracelab.viewers.replay.markdown_text import literal

from tracelab.store.eval_params import EVAL_PARAMS_COLUMNS, eval_params_text
from tracelab.store.reader import RunConnection

REWARD_PALER = 0.5      # a reward line's team colour, this far towards white


StepRow = tuple[int, str, float, str]     # t, agent, reward, action (its name, else its number)


def step_rows(con: RunConnection, episodes: list[int]) -> dict[int, list[StepRow]]:
    """episode -> its `steps` rows (t, agent, reward, action) in t order, for all these episodes in one
    query (`t`: the timestep an env step ended at, the replay's `step`)."""
    out: dict[int, list[StepRow]] = {}
    for episode, step, agent, reward, action in con.execute(
            "SELECT episode, t, agent, reward, coalesce(action_name, action::VARCHAR) FROM steps "
            "WHERE episode IN (SELECT unnest(?::BIGINT[])) ORDER BY episode, t, agent", [list(episodes)]).fetchall():
        out.setdefault(episode, []).append((step, agent, reward, action))
    return out


def step_notes(rows: list[StepRow]) -> dict[int, list[str]]:
    """t -> the step document's lines of what the agents did and got in that step."""
    by_t: dict[int, list[StepRow]] = {}
    for row in rows:
        by_t.setdefault(row[0], []).append(row)
    return {t: [f"- actions: {', '.join(f'{literal(a)} {literal(act)}' for _, a, _, act in at)}",
                f"- reward: {', '.join(f'{literal(a)} {r:g}' for _, a, r, _ in at)}"] for t, at in by_t.items()}


def eval_game_note(con: RunConnection, episode: int) -> str | None:
    """The step document's line that says what an evaluation game was played against (the world's params, an
    older run's opponent level) and places a training's in its training (its begin info, docs/store.md's
    training-run contract), None for any other episode: the replay has no training curves (module
    docstring), this is what it shows of them."""
    rows = con.execute(
        "SELECT TRY_CAST(json_extract(begin_info, '$.train_step') AS BIGINT), "
        "TRY_CAST(json_extract(begin_info, '$.eval_round') AS BIGINT), "
        f"{EVAL_PARAMS_COLUMNS} FROM episodes "
        "WHERE episode = ? AND json_extract_string(begin_info, '$.kind') = 'eval'", [episode]).fetchall()
    if not rows:
        return None
    train_step, eval_round, params, level = rows[0]
    played_against = eval_params_text(params, level)
    where = [f"at train step {train_step:,}" if train_step is not None else "",
             f"round {eval_round}" if eval_round is not None else "",
             literal(played_against) if played_against is not None else ""]
    where = ", ".join(w for w in where if w)
    if train_step is None and eval_round is None:  # tracelab eval --run's: no training to place it in
        return "- an evaluation game" + (f", {where}" if where else "")
    return f"- an evaluation game of the training, {where} (its curves: `tracelab tui RUN`, 6 Training)"


def agent_rewards(agents: list[str], rows: list[StepRow]) -> np.ndarray | None:
    """[last t + 1, len(agents)] each agent's reward per timestep (0 where it took no step) from the
    episode's `steps` rows, or None when the run has none for it."""
    if not rows:
        return None
    column = {a: i for i, a in enumerate(agents)}
    out = np.zeros((max(t for t, *_ in rows) + 1, len(agents)))
    for t, agent, reward, _ in rows:
        if t >= 0 and agent in column:
            out[t, column[agent]] += reward
    return out


@cache
def _series_style(name: str, kind: str, colour: tuple[int, int, int]) -> rr.SeriesLines:
    """A series' line style, built once (an archetype converts its data to Arrow when it is made)."""
    c = np.asarray(colour, float)
    if kind == "reward":  # paler than the return: the legend's dots tell the two apart
        c += (255 - c) * REWARD_PALER
    return rr.SeriesLines(colors=[int(v) for v in c], names=f"{name} {kind}", widths=2.0 if kind == "return" else 1.0)


def log_rewards(rec: rr.RecordingStream, rewards: np.ndarray, names: list[str],
                colours: list[tuple[int, int, int] | None] | None = None) -> None:
    """Each column of `rewards` ([steps, len(names)]: an agent's reward at each step) as its reward and its
    return (the running sum), in `colours` (None, or a None in it: the palette's)."""
    palette = [style.SERIES_COLORS[i % len(style.SERIES_COLORS)] for i in range(len(names))]
    colours = [c or p for c, p in zip(colours or [None] * len(names), palette)]
    steps = np.arange(len(rewards))
    series = [(name, kind, values) for i, name in enumerate(names)
              for kind, values in (("reward", rewards[:, i]), ("return", np.cumsum(rewards[:, i])))]
    for (name, kind, _), colour in zip(series, [c for c in colours for _ in range(2)]):
        rec.log(f"{style.PLOTS}/{kind}/{name}", _series_style(name, kind, colour), static=True)
    every = np.tile(steps, len(series))
    send_per_entity(rec, [f"{style.PLOTS}/{kind}/{name}" for name, kind, _ in series], [len(steps)] * len(series),
                    [rr.TimeColumn(style.STEP, sequence=every)],
                    rr.Scalars.columns(scalars=np.concatenate([v for _, _, v in series])))

