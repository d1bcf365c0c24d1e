"""Why an agent did what it did at a step, read from a run (`tracelab why RUN --action AGENT`, `why-not
--action NAME`): the recorded decision (the chosen action, the others ranked by the policy's value with
the margin, greedy or explored, the mask), the observation it acted on named from the run's
observation_names (each index part's value with the atom it was read from, which `tracelab why` explains
in turn), and the reward terms the step received; for a decomposed policy (train --decompose), each
action's expected return by reward term. Everything is in the run: no policy is loaded."""
from __future__ import annotations

from typing import Any, NamedTuple

from tracelab.engine.terminal_text import printable
from tracelab.store.reader import RunConnection

# Records are NamedTuples and plain classes, not dataclasses: a dataclass costs ~1-2 ms of CPU to create at
# import, and `why --action` is asked over and over (issue 40).


class ActionValue(NamedTuple):
    name: str
    value: float
    allowed: bool


class Feature(NamedTuple):
    name: str
    value: str          # as shown: a number, or the atom an index stands for
    atom: str | None    # the atom it was read from (an index part's), for `tracelab why`


class ActionExplanation:
    """The decision of an agent at a step, with what it read and the reward it got."""

    def __init__(self, episode: int, step: int, agent: str, action: str, output: str, explored: bool,
                 epsilon: float | None, state_value: float | None, ranked: list[ActionValue]) -> None:
        self.episode, self.step, self.agent, self.action = episode, step, agent, action
        self.output = output                  # "q" (Q-values) or "logits"
        self.explored, self.epsilon, self.state_value = explored, epsilon, state_value
        self.ranked = ranked                  # every action, highest value first
        self.features: list[Feature] = []
        self.observed_at: int | None = None   # the step whose recorded observation the agent acted on (None: the start)
        self.terms: list[tuple[str, float]] = []
        self.reward: float | None = None
        # a decomposed policy's Q-values by reward term: term -> {action: value} (empty for any other policy)
        self.by_term: dict[str, dict[str, float]] = {}

    @property
    def chosen(self) -> ActionValue:
        return next(a for a in self.ranked if a.name == self.action)

    @property
    def margin(self) -> float | None:
        """The chosen action's value minus the best other allowed action's (None: no other allowed)."""
        others = [a.value for a in self.ranked if a.name != self.action and a.allowed]
        return None if not others else self.chosen.value - max(others)

    def to_dict(self) -> dict[str, Any]:
        return {"episode": self.episode, "step": self.step, "agent": self.agent, "action": self.action,
                "output": self.output, "explored": self.explored, "epsilon": self.epsilon,
                "state_value": self.state_value, "margin": self.margin,
                "ranked": [a._asdict() for a in self.ranked], "observed_at": self.observed_at,
                "features": [f._asdict() for f in self.features],
                "reward": self.reward, "terms": [{"term": t, "value": v} for t, v in self.terms],
                "q_by_term": self.by_term}


# The decision, the run's action names, the observation it read (recorded after the step before), the
# observation's names, the reward terms and the reward: one statement (each costs its own planning, ~2 ms of CPU
# on a cold process), on the raw tables (the `decisions` and `rewards` views cost their own binding and a join
# each: ~5 ms of a cold `why --action`; the names are matched here as the `decisions` view matches them); lists,
# not scalar subqueries (whose check for a second row costs more planning)
_DECISION_SQL = """
SELECT action, output, explored, epsilon, state_value, "values", mask, terms, term_values,
       (SELECT list((action, name, position)) FROM raw.action_names),
       (SELECT list(obs) FROM raw.steps WHERE episode = $episode AND step = $step - 1 AND agent = $agent),
       (SELECT list((position, name, divisor, size, labels) ORDER BY position, divisor DESC)
        FROM raw.observation_names),
       (SELECT list((term, value) ORDER BY abs(value) DESC, term)
        FROM raw.reward_terms WHERE episode = $episode AND step = $step AND agent = $agent),
       (SELECT list(reward) FROM raw.steps WHERE episode = $episode AND step = $step AND agent = $agent)
FROM raw.decisions WHERE episode = $episode AND step = $step AND agent = $agent"""


def explain_action(con: RunConnection, episode: int, agent: str, step: int) -> ActionExplanation:
    """The decision of `agent` at `step` of `episode` with its observation and reward terms (KeyError,
    naming what the run has, when there is none)."""
    rows = con.execute(_DECISION_SQL, {"episode": episode, "step": step, "agent": agent}).fetchall()
    if not rows:
        raise KeyError(_no_decision(con, episode, agent, step))
    (action, output, explored, epsilon, state_value, values, mask, term_names, term_values,
     action_names, obs, parts, terms, reward) = rows[0]
    name, actions = _action_names(action, action_names or [])
    allowed = mask if mask is not None else [True] * len(values)
    ranked = sorted((ActionValue(str(a), float(v), bool(m)) for a, v, m in zip(actions, values, allowed)),
                    key=lambda a: -a.value)
    e = ActionExplanation(episode, step, agent, str(name), str(output), bool(explored), epsilon, state_value, ranked)
    if term_names and term_values and len(term_values) == len(term_names) * len(actions):
        a = len(actions)
        e.by_term = {str(t): {str(n): float(v) for n, v in zip(actions, term_values[k * a:(k + 1) * a])}
                     for k, t in enumerate(term_names)}
    if step > 1:
        e.observed_at = step - 1
        e.features = _features(obs[0] if obs else None, parts or [])
    e.terms = [(str(t), float(v)) for t, v in terms or []]
    e.reward = float(reward[0]) if reward else None
    return e


def _action_names(action: int, rows: list[tuple[int, str, int | None]]) -> tuple[str | None, list[str]]:
    """The chosen action's name and the names of the actions the policy's values are of (in their order), from
    raw.action_names' rows (action, name, position), as the `decisions` view reads them (tracelab.store.schema):
    the name of the action-th action by number, and those with a position, in its order."""
    by_number = [n for _, n, _ in sorted(rows, key=lambda r: r[0])]
    offered = [n for _, n, p in sorted((r for r in rows if r[2] is not None), key=lambda r: r[2])]
    return (by_number[action] if action is not None and 0 <= action < len(by_number) else None), offered


def _no_decision(con: RunConnection, episode: int, agent: str, step: int) -> str:
    have = con.execute("SELECT count(*), min(step), max(step), list(DISTINCT agent ORDER BY agent) FROM raw.decisions "
                       "WHERE episode = ?", [episode]).fetchall()[0]
    if not con.execute("SELECT count(*) FROM raw.decisions").fetchall()[0][0]:
        return ("the run records no decisions (written before tracelab recorded them, or its games were not "
                "played by a trained policy: play --policy, eval --run, train's evaluations record them)")
    if not have[0]:
        return f"episode {episode} records no decisions"
    if agent not in have[3]:
        agents = ", ".join(map(printable, have[3]))
        return f"no decisions of agent {printable(agent)} in episode {episode}; its agents: {agents}"
    return (f"no decision of {printable(agent)} at step {step} of episode {episode} "
            f"(it decided at steps {have[1]}..{have[2]})")


def _features(values: list[float] | None, names: list[tuple[Any, ...]]) -> list[Feature]:
    """The observation a decision read (`values`: the one recorded after the step before; the start's is not
    recorded), named by observation_names' rows (position, name, divisor, size, labels)."""
    if values is None:
        return []
    if not names:
        return [Feature(f"obs[{i}]", f"{v:g}", None) for i, v in enumerate(values)]
    out = []
    for position, name, divisor, size, labels in names:
        if position >= len(values):
            continue
        v = values[position]
        if size is not None:
            v = (int(v) // divisor) % size
        atom = labels[int(v)] if labels is not None and float(v).is_integer() and 0 <= v < len(labels) else None
        out.append(Feature(str(name), atom if atom is not None else f"{v:g}", atom))
    return out


class WhyNotAction(NamedTuple):
    explanation: ActionExplanation
    name: str
    masked: bool
    gap: float   # the chosen action's value minus this one's

    def to_dict(self) -> dict[str, Any]:
        return {"action": self.name, "chosen": self.explanation.action, "masked": self.masked, "gap": self.gap,
                "explored": self.explanation.explored, "episode": self.explanation.episode,
                "step": self.explanation.step, "agent": self.explanation.agent}


def why_not_action(e: ActionExplanation, name: str) -> WhyNotAction:
    """Why `name` was not taken at e's step: the mask refused it, or its value fell short by `gap`."""
    match = [a for a in e.ranked if a.name == name]
    if not match:
        raise KeyError(f"no action {printable(name)}: the actions are {', '.join(printable(a.name) for a in e.ranked)}")
    a = match[0]
    return WhyNotAction(e, name, not a.allowed, e.chosen.value - a.value)


# ---- text ----

def render_action(e: ActionExplanation, run: str = "RUN") -> str:
    what = "Q-value" if e.output == "q" else "logit"
    how = (f"explored (ε = {e.epsilon:g}): a random action, not the policy's choice" if e.explored
           else "greedy" + (f" (ε = {e.epsilon:g})" if e.epsilon else ""))
    margin = e.margin
    lines = [f"{printable(e.agent)} at step {e.step} of episode {e.episode}: {printable(e.action)}, {how}",
             f"  {what} {e.chosen.value:.4g}" + ("" if margin is None else
                                                f", {margin:+.4g} over the next allowed action")
             + ("" if e.state_value is None else f"; state value {e.state_value:.4g}")]
    lines.append(f"actions by {what}:")
    for a in e.ranked:
        mark = "->" if a.name == e.action else "  "
        gap = "" if a.name == e.action else f"  ({a.value - e.chosen.value:+.4g})"
        lines.append(f"  {mark} {printable(a.name):<14} {a.value:>10.4g}{gap}{'' if a.allowed else '  masked'}")
    if e.by_term:
        lines.append("expected return by reward term (the Q-value's heads, summing to it):")
        names = [printable(t) for t in e.by_term]
        widths = [max(10, len(n)) for n in names]
        lines.append("     " + " " * 14 + "".join(f" {n:>{w}}" for n, w in zip(names, widths)))
        for a in e.ranked:
            mark = "->" if a.name == e.action else "  "
            lines.append(f"  {mark} {printable(a.name):<14}"
                         + "".join(f" {v[a.name]:>{w}.4g}" for v, w in zip(e.by_term.values(), widths)))
    if e.observed_at is None:
        lines.append("observation: the episode's start (not recorded)")
    else:
        lines.append(f"observation (recorded after step {e.observed_at}):")
        for f in e.features:
            lines.append(f"  {printable(f.name)} = {printable(f.value)}")
        atoms = [f.atom for f in e.features if f.atom is not None]
        if atoms:
            lines.append(f"  why an atom held: tracelab why {run} '{printable(atoms[0])}' --episode {e.episode} "
                         f"--at {e.observed_at}")
    if e.reward is not None:
        terms = ", ".join(f"{printable(t)} {v:+g}" for t, v in e.terms) or "no term"
        lines.append(f"reward {e.reward:+g}: {terms}")
    return "\n".join(lines)


def render_why_not_action(w: WhyNotAction) -> str:
    e = w.explanation
    head = (f"{printable(e.agent)} at step {e.step} of episode {e.episode} took {printable(e.action)}, "
            f"not {printable(w.name)}")
    if w.name == e.action:
        return f"{printable(e.agent)} did take {printable(w.name)} at step {e.step} of episode {e.episode}"
    if w.masked:
        return f"{head}: the action mask did not allow {printable(w.name)}"
    if e.explored:
        return f"{head}: the action was explored (a random one, ε = {e.epsilon:g}), not chosen by value"
    value = next(a.value for a in e.ranked if a.name == w.name)
    return (f"{head}: its value {value:.4g} is {w.gap:.4g} below {printable(e.action)}'s {e.chosen.value:.4g}"
            f" (rank {[a.name for a in e.ranked].index(w.name) + 1} of {len(e.ranked)})")
