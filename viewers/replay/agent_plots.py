"""The agent's half of an episode as plots (the run's `decisions` and `rewards` views, docs/store.md): the
policy's value of every action per step, a series per action (/values/AGENT/ACTION), and each agent's
return by reward term, stacked under its return (/terms/AGENT/TERM, /terms/AGENT/return): the deciding
agents' where the policy decided for some (the learners, beside a scripted opponent), else every agent's. A run without
decisions or reward terms (written before they were recorded, or played by a scripted policy) has none."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import rerun as rr

from tracelab.store.reader import RunConnection
from tracelab.viewers.replay import style
from tracelab.viewers.replay.columns import send_per_entity

RETURN = "return"      # the top line of an agent's stacked terms


@dataclass
class AgentSeries:
    """One episode's series on the replay's `step` timeline (steps.t): name -> (t, values)."""
    values: dict[tuple[str, str], tuple[list[int], list[float]]] = field(default_factory=dict)
    terms: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict)  # agent -> term


def read_series(con: RunConnection, episode: int) -> AgentSeries:
    """The action values and the running return by term of every agent in `episode` (three queries)."""
    out = AgentSeries()
    for t, agent, actions, values in con.execute(
            "SELECT s.t, d.agent, d.actions, d.\"values\" FROM decisions d JOIN steps s USING (episode, step, agent) "
            "WHERE d.episode = ? ORDER BY s.t, d.agent", [episode]).fetchall():
        for action, value in zip(actions or (), values or ()):
            ts, vs = out.values.setdefault((agent, action), ([], []))
            ts.append(t)
            vs.append(value)
    rows = con.execute("SELECT s.t, r.agent, r.term, sum(r.value) FROM rewards r "
                       "JOIN steps s USING (episode, step, agent) WHERE r.episode = ? "
                       "GROUP BY ALL ORDER BY r.agent, r.term, s.t", [episode]).fetchall()
    if not rows:
        return out
    steps: dict[str, np.ndarray] = {}
    for agent, ts in con.execute("SELECT agent, list(DISTINCT t ORDER BY t) FROM steps WHERE episode = ? "
                                 "GROUP BY agent", [episode]).fetchall():
        steps[agent] = np.asarray(ts, np.int64)
    per_term: dict[str, dict[str, np.ndarray]] = {}
    for t, agent, term, value in rows:
        ts = steps.get(agent)
        if ts is None:
            continue
        running = per_term.setdefault(agent, {}).setdefault(term, np.zeros(len(ts)))
        running[np.searchsorted(ts, t):] += value     # a running sum: the term's return up to each step
    # a run whose policy decided for some agents (a scripted opponent beside them): theirs only
    deciders = {agent for agent, _ in out.values}
    for agent, terms in per_term.items():
        if deciders and agent not in deciders:
            continue
        ts, stacked, below = steps[agent], {}, np.zeros(len(steps[agent]))
        # the largest terms at the bottom: each line is its term's running return on top of the ones below
        for term in sorted(terms, key=lambda k: (-abs(terms[k][-1]), k)):
            below = below + terms[term]
            stacked[term] = (ts, below)
        stacked[RETURN] = (ts, below.copy())
        out.terms[agent] = stacked
    return out


def _part(name: str) -> str:
    return rr.escape_entity_path_part(name)


def log_agent_series(rec: rr.RecordingStream, series: AgentSeries,
                     colour_of: Callable[[str], tuple[int, int, int] | None] = lambda agent: None) -> None:
    """The values per action (one colour per action, named by it; by agent too when several decide) and
    the stacked terms under each agent's return (in `colour_of(agent)`: its piece's on the board; else
    white)."""
    deciders = {agent for agent, _ in series.values}
    actions = list(dict.fromkeys(action for _, action in series.values))
    lines: list[tuple[str, list[int] | np.ndarray, list[float] | np.ndarray]] = []
    for (agent, action), (ts, vs) in series.values.items():
        path = f"{style.VALUES}/{_part(agent)}/{_part(action)}"
        name = action if len(deciders) == 1 else f"{agent} {action}"
        colour = style.SERIES_COLORS[actions.index(action) % len(style.SERIES_COLORS)]
        rec.log(path, rr.SeriesLines(colors=[colour], names=name, widths=1.5), static=True)
        lines.append((path, ts, vs))
    for agent, stacked in series.terms.items():
        for i, (term, (ts, vs)) in enumerate(stacked.items()):
            path = f"{style.TERMS}/{_part(agent)}/{_part(term)}"
            top = term == RETURN
            colour = (colour_of(agent) or (255, 255, 255)) if top else style.SERIES_COLORS[i % len(style.SERIES_COLORS)]
            name = f"{agent} {term}" if len(series.terms) > 1 else term
            rec.log(path, rr.SeriesLines(colors=[tuple(int(c) for c in colour)], names=name,
                                         widths=2.5 if top else 1.0), static=True)
            lines.append((path, ts, vs))
    if not lines:
        return
    every = np.concatenate([np.asarray(ts, np.int64) for _, ts, _ in lines])
    send_per_entity(rec, [p for p, _, _ in lines], [len(ts) for _, ts, _ in lines],
                    [rr.TimeColumn(style.STEP, sequence=every)],
                    rr.Scalars.columns(scalars=np.concatenate([np.asarray(vs, np.float64) for _, _, vs in lines])))
