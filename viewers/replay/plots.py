"""Plots: each team's reward and return per step of an episode (from the run's `steps` rows), and a
training run's curves (its `metrics` rows, docs/store.md and the training-run contract) on their own
`train_step` timeline."""
from __future__ import annotations

from functools import cache

import numpy as np
import rerun as rr
from tracelab.viewers.replay import style
from tracelab.viewers.replay.columns import send_per_entity

from tracelab.viewers.board import TEAMS, EpisodeBoard
from tracelab.store.reader import RunConnection

REWARD_PALER = 0.5      # a reward line's team colour, this far towards white


def step_rewards(con: RunConnection, episodes: list[int]) -> dict[int, list[tuple[int, str, float]]]:
    """episode -> its `steps` rows (step, agent, reward), for all these episodes in one query."""
    out: dict[int, list[tuple[int, str, float]]] = {}
    for episode, step, agent, reward in con.execute(
            "SELECT episode, step, agent, reward FROM steps WHERE episode IN (SELECT unnest(?::BIGINT[]))",
            [list(episodes)]).fetchall():
        out.setdefault(episode, []).append((step, agent, reward))
    return out


def team_rewards(board: EpisodeBoard, rows: list[tuple[int, str, float]]) -> np.ndarray | None:
    """[steps + 1, 2] each team's reward per step (the sum of its agents'; step 0 is 0) from the
    episode's `steps` rows, or None when the run has none for it."""
    if not rows:
        return None
    team_of = dict(zip(board.agents, board.agent_team.tolist()))
    out = np.zeros((board.steps + 1, 2))
    for step, agent, reward in rows:
        if 0 <= step <= board.steps and agent in team_of:
            out[step, team_of[agent]] += reward
    return out


@cache
def _series_style(team: str, kind: str) -> rr.SeriesLines:
    """A series' line style, built once (an archetype converts its data to Arrow when it is made)."""
    colour = style.TEAM_COLOR[TEAMS.index(team)].astype(float)
    if kind == "reward":  # paler than the return: the legend's dots tell the two apart
        colour += (255 - colour) * REWARD_PALER
    return rr.SeriesLines(colors=[int(c) for c in colour], names=f"{team} {kind}",
                          widths=2.0 if kind == "return" else 1.0)


def log_rewards(rec: rr.RecordingStream, rewards: np.ndarray) -> None:
    steps = np.arange(len(rewards))
    series = [(team, kind, values) for t, team in enumerate(TEAMS)
              for kind, values in (("reward", rewards[:, t]), ("return", np.cumsum(rewards[:, t])))]
    for team, kind, _ in series:
        rec.log(f"{style.PLOTS}/{kind}/{team}", _series_style(team, kind), static=True)
    every = np.tile(steps, len(series))
    send_per_entity(rec, [f"{style.PLOTS}/{kind}/{team}" for team, kind, _ in series], [len(steps)] * len(series),
                    [rr.TimeColumn(style.STEP, sequence=every),
                     rr.TimeColumn(style.PASS, sequence=style.pass_time(every, 0))],
                    rr.Scalars.columns(scalars=np.concatenate([v for _, _, v in series])))


def training_metrics(con: RunConnection) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """name -> (training steps, values) of a run's metrics (empty for a run that logged none)."""
    rows = con.execute("SELECT name, step, value FROM metrics WHERE value IS NOT NULL "
                       "ORDER BY name, step").fetchall()
    out: dict[str, tuple[list[int], list[float]]] = {}
    for name, step, value in rows:
        s, v = out.setdefault(name, ([], []))
        s.append(step)
        v.append(value)
    return {k: (np.asarray(s, np.int64), np.asarray(v, np.float64)) for k, (s, v) in out.items()}


def log_training(rec: rr.RecordingStream, metrics: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    """Each metric as a series under /train (eval/win_rate -> /train/eval/win_rate; an opponent suffix
    such as @p0.3 becomes a path part), on the train_step timeline."""
    if not metrics:
        return
    send_per_entity(rec, [f"{style.TRAIN}/{name.replace('@', '/')}" for name in metrics],
                    [len(steps) for steps, _ in metrics.values()],
                    [rr.TimeColumn(style.TRAIN_STEP, sequence=np.concatenate([s for s, _ in metrics.values()]))],
                    rr.Scalars.columns(scalars=np.concatenate([v for _, v in metrics.values()])))
