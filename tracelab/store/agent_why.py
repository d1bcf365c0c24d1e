"""Why an agent did what it did at a step, read from a run (`tracelab why RUN --action AGENT`, `why-not
--action NAME`): the recorded decision (the chosen action, the others ranked by the policy's value with
the margin, greedy or explored, the mask), the observation it acted on named from the run's
observation_names (each index part's value with the atom it was read from, which `tracelab why` explains
in turn), and the reward terms the step received; for a decomposed policy (train --decompose), each
action's expected return by reward term. Everything is in the run: no policy is loaded."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from tracelab.engine.terminal_text import printable
from tracelab.store.reader import RunConnection


@dataclass(frozen=True)
class ActionValue:
    name: str
    value: float
    allowed: bool


@dataclass(frozen=True)
class Feature:
    name: str
    value: str          # as shown: a number, or the atom an index stands for
    atom: str | None    # the atom it was read from (an index part's), for `tracelab why`


@dataclass
class ActionExplanation:
    episode: int
    step: int
    agent: str
    action: str
    output: str                      # "q" (Q-values) or "logits"
    explored: bool
    epsilon: float | None
    state_value: float | None
    ranked: list[ActionValue]        # every action, highest value first
    features: list[Feature] = field(default_factory=list)
    observed_at: int | None = None   # the step whose recorded observation the agent acted on (None: the start)
    terms: list[tuple[str, float]] = field(default_factory=list)
    reward: float | None = None
    # a decomposed policy's Q-values by reward term: term -> {action: value} (empty for any other policy)
    by_term: dict[str, dict[str, float]] = field(default_factory=dict)

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
                "ranked": [a.__dict__ for a in self.ranked], "observed_at": self.observed_at,
                "features": [f.__dict__ for f in self.features],
                "reward": self.reward, "terms": [{"term": t, "value": v} for t, v in self.terms],
                "q_by_term": self.by_term}


def explain_action(con: RunConnection, episode: int, agent: str, step: int) -> ActionExplanation:
    """The decision of `agent` at `step` of `episode` with its observation and reward terms (KeyError,
    naming what the run has, when there is none)."""
    rows = con.execute("SELECT action_name, output, explored, epsilon, state_value, actions, \"values\", mask, "
                       "terms, term_values FROM decisions WHERE episode = ? AND step = ? AND agent = ?",
                       [episode, step, agent]).fetchall()
    if not rows:
        raise KeyError(_no_decision(con, episode, agent, step))
    name, output, explored, epsilon, state_value, actions, values, mask, term_names, term_values = rows[0]
    allowed = mask if mask is not None else [True] * len(values)
    ranked = sorted((ActionValue(str(a), float(v), bool(m)) for a, v, m in zip(actions, values, allowed)),
                    key=lambda a: -a.value)
    e = ActionExplanation(episode, step, agent, str(name), str(output), bool(explored), epsilon, state_value, ranked)
    if term_names and term_values and len(term_values) == len(term_names) * len(actions):
        a = len(actions)
        e.by_term = {str(t): {str(n): float(v) for n, v in zip(actions, term_values[k * a:(k + 1) * a])}
                     for k, t in enumerate(term_names)}
    e.observed_at, e.features = _features(con, episode, agent, step)
    terms = con.execute("SELECT term, value FROM rewards WHERE episode = ? AND step = ? AND agent = ? "
                        "ORDER BY abs(value) DESC, term", [episode, step, agent]).fetchall()
    e.terms = [(str(t), float(v)) for t, v in terms]
    reward = con.execute("SELECT reward FROM raw.steps WHERE episode = ? AND step = ? AND agent = ?",
                         [episode, step, agent]).fetchall()
    e.reward = float(reward[0][0]) if reward else None
    return e


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


def _features(con: RunConnection, episode: int, agent: str, step: int) -> tuple[int | None, list[Feature]]:
    """The observation the decision at `step` read: the one recorded after step - 1 (the start's is not
    recorded), named by observation_names."""
    if step <= 1:
        return None, []
    obs = con.execute("SELECT obs FROM raw.steps WHERE episode = ? AND step = ? AND agent = ?",
                      [episode, step - 1, agent]).fetchall()
    if not obs or obs[0][0] is None:
        return step - 1, []
    values = obs[0][0]
    names = con.execute("SELECT position, name, divisor, size, labels FROM raw.observation_names "
                        "ORDER BY position, divisor DESC").fetchall()
    if not names:
        return step - 1, [Feature(f"obs[{i}]", f"{v:g}", None) for i, v in enumerate(values)]
    out = []
    for position, name, divisor, size, labels in names:
        if position >= len(values):
            continue
        v = values[position]
        if size is not None:
            v = (int(v) // divisor) % size
        atom = labels[int(v)] if labels is not None and float(v).is_integer() and 0 <= v < len(labels) else None
        out.append(Feature(str(name), atom if atom is not None else f"{v:g}", atom))
    return step - 1, out


@dataclass(frozen=True)
class WhyNotAction:
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
