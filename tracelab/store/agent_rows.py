"""The agent's half of a traced step, as the store records it: what the policy valued and chose
(`Decisions`, a row per agent and step: the action, the policy's output for every action, explored or
greedy, ε, the action mask) and what its reward was made of (`RewardTerms`, a row per agent, step and
non-zero term, summing to the step's reward). Both of a run's tracers (RuleSim's StoreSink, in the runs it
wrote, and a declared world's DeclaredRecorder) keep them in an `AgentRows` and write them with it, before
the episode ends they belong to (tables decisions, reward_terms and action_names: tracelab/store/schema.py)."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
import pyarrow as pa

from tracelab.store import arrow_build as ab
from tracelab.store.schema import SCHEMAS

Q_VALUES, LOGITS = "q", "logits"  # what a decision's `values` are


@dataclass(frozen=True)
class PolicyOutput:
    """A policy's output for a batch of B decisions: `values` [B, A] (Q-values, or an actor's logits), in
    the order of the policy's actions; an actor-critic's state values [B] (None otherwise); whether each
    action was explored (None: all greedy) and the ε it explored with; a decomposed Q-network's values by
    reward term `term_values` [B, len(terms), A] (they sum to `values`)."""
    values: np.ndarray
    output: str = Q_VALUES
    state_value: np.ndarray | None = None
    explored: np.ndarray | None = None
    epsilon: float = 0.0
    terms: tuple[str, ...] = ()
    term_values: np.ndarray | None = None

    @staticmethod
    def concat(outputs: Sequence["PolicyOutput"]) -> "PolicyOutput":
        """One batch of the decisions of several (of one policy: one output kind and ε)."""
        first = outputs[0]
        return PolicyOutput(
            np.concatenate([o.values for o in outputs]), first.output,
            None if first.state_value is None else np.concatenate([o.state_value for o in outputs]),
            None if first.explored is None else np.concatenate([o.explored for o in outputs]), first.epsilon,
            first.terms, None if first.term_values is None else np.concatenate([o.term_values for o in outputs]))

    def rows(self, keep: np.ndarray | slice) -> "PolicyOutput":
        """The decisions at `keep` (a mask or index over the batch)."""
        return replace(self, values=self.values[keep],
                       state_value=None if self.state_value is None else self.state_value[keep],
                       explored=None if self.explored is None else self.explored[keep],
                       term_values=None if self.term_values is None else self.term_values[keep])


def coded_strings(codes: np.ndarray, names: Sequence[str]) -> pa.Array:
    """names[codes] as an Arrow string array (ab.coded_strings: no Python string per row)."""
    return ab.coded_strings(np.asarray(codes, np.int64), names)


@dataclass(frozen=True)
class Decisions:
    """Decision rows: each row's episode, step (steps.step), agent (a code: agents[code] is its name), the
    action taken (as steps.action holds it) and the policy's output (one row of `policy` per decision);
    `mask` [K, A]: the allowed actions (None: no mask)."""
    episode: np.ndarray
    step: np.ndarray
    agent: np.ndarray
    agents: Sequence[str]
    action: np.ndarray
    policy: PolicyOutput
    mask: np.ndarray | None = None

    def rows(self, keep: np.ndarray, episode: np.ndarray | None = None) -> "Decisions":
        """The rows at `keep` (a mask), with `episode` as their episodes if given."""
        return Decisions(self.episode[keep] if episode is None else episode, self.step[keep], self.agent[keep],
                         self.agents, self.action[keep], self.policy.rows(keep),
                         None if self.mask is None else self.mask[keep])

    @staticmethod
    def concat(batches: Sequence["Decisions"]) -> "Decisions":
        """One batch of several of one tracer's (the same agents, policy output kind and mask or none)."""
        first = batches[0]
        if len(batches) == 1:
            return first
        return Decisions(*(np.concatenate([getattr(b, f) for b in batches]) for f in ("episode", "step", "agent")),
                         first.agents, np.concatenate([b.action for b in batches]),
                         PolicyOutput.concat([b.policy for b in batches]),
                         None if first.mask is None else np.concatenate([b.mask for b in batches]))

    def table(self) -> pa.Table:
        n, values = len(self.episode), np.ascontiguousarray(self.policy.values, np.float32)
        a = values.shape[1] if values.ndim == 2 else 0
        offsets = np.arange(n + 1, dtype=np.int32) * a
        p = self.policy
        explored = np.zeros(n, bool) if p.explored is None else np.asarray(p.explored, bool)
        mask = pa.nulls(n, pa.list_(pa.bool_())) if self.mask is None else \
            ab.list_array(offsets, ab.from_numpy(np.asarray(self.mask, bool).reshape(-1)))
        return pa.Table.from_arrays([
            ab.from_numpy(np.asarray(self.episode, np.int64)), ab.from_numpy(np.asarray(self.step, np.int32)),
            coded_strings(self.agent, self.agents), ab.from_numpy(np.asarray(self.action, np.int32)),
            coded_strings(np.zeros(n, np.int32), [p.output]),
            ab.list_array(offsets, ab.from_numpy(values.reshape(-1))),
            ab.from_numpy(np.full(n, np.nan) if p.state_value is None else np.asarray(p.state_value, np.float64),
                          null=np.ones(n, bool) if p.state_value is None else None),
            ab.from_numpy(explored), ab.from_numpy(np.full(n, float(p.epsilon))), mask, *self._term_columns(n),
        ], schema=SCHEMAS["decisions"])

    def _term_columns(self, n: int) -> tuple[pa.Array, pa.Array]:
        """`terms` and `term_values` (NULL unless the policy is decomposed by reward term)."""
        p = self.policy
        if p.term_values is None:
            return pa.nulls(n, SCHEMAS["decisions"].field("terms").type), \
                pa.nulls(n, SCHEMAS["decisions"].field("term_values").type)
        flat = np.ascontiguousarray(p.term_values, np.float32).reshape(n, -1)
        k = len(p.terms)
        return (ab.list_array(np.arange(n + 1, dtype=np.int32) * k, ab.strings(list(p.terms) * n)),
                ab.list_array(np.arange(n + 1, dtype=np.int32) * flat.shape[1], ab.from_numpy(flat.reshape(-1))))


@dataclass(frozen=True)
class RewardTerms:
    """Reward-term rows: episode, step, agent and term (codes: agents[code], terms[code] their names),
    value, and `quantity`: what the term's value per occurrence multiplied (a table term's occurrences in
    the step, a scaled atom's bound; None: not known). `table` keeps the rows where the term was paid:
    its value or its quantity is not 0, so a term worth 0 that occurred keeps a row of value 0."""
    episode: np.ndarray
    step: np.ndarray
    agent: np.ndarray
    agents: Sequence[str]
    term: np.ndarray
    terms: Sequence[str]
    value: np.ndarray
    quantity: np.ndarray | None = None

    def rows(self, keep: np.ndarray, episode: np.ndarray | None = None) -> "RewardTerms":
        """The rows at `keep` (a mask), with `episode` as their episodes if given."""
        return RewardTerms(self.episode[keep] if episode is None else episode, self.step[keep], self.agent[keep],
                           self.agents, self.term[keep], self.terms, self.value[keep],
                           None if self.quantity is None else self.quantity[keep])

    @staticmethod
    def concat(batches: Sequence["RewardTerms"]) -> "RewardTerms":
        first = batches[0]
        if len(batches) == 1:
            return first
        cols = {f: np.concatenate([getattr(b, f) for b in batches]) for f in ("episode", "step", "agent", "term",
                                                                                "value")}
        quantity = None if any(b.quantity is None for b in batches) else \
            np.concatenate([b.quantity for b in batches])
        return RewardTerms(cols["episode"], cols["step"], cols["agent"], first.agents, cols["term"], first.terms,
                           cols["value"], quantity)

    def table(self) -> pa.Table:
        value = np.asarray(self.value, np.float64)
        if self.quantity is None:
            keep = np.flatnonzero(value != 0.0)
            quantity = pa.nulls(len(keep), pa.float64())
        else:
            q = np.asarray(self.quantity, np.float64)
            keep = np.flatnonzero((value != 0.0) | (q != 0.0))
            quantity = ab.from_numpy(q[keep])
        return pa.Table.from_arrays([
            ab.from_numpy(np.asarray(self.episode, np.int64)[keep]),
            ab.from_numpy(np.asarray(self.step, np.int32)[keep]),
            coded_strings(np.asarray(self.agent)[keep], self.agents),
            coded_strings(np.asarray(self.term)[keep], self.terms), ab.from_numpy(value[keep]), quantity,
        ], schema=SCHEMAS["reward_terms"])


def action_names_table(names: Sequence[str], positions: Sequence[int | None] | None = None) -> pa.Table:
    """The run's actions: action k (as steps.action holds it) is names[k], at positions[k] in a decision's
    values (default: k)."""
    n = len(names)
    pos = list(range(n)) if positions is None else list(positions)
    missing = np.array([p is None for p in pos], bool)
    return pa.Table.from_arrays([
        ab.from_numpy(np.arange(n, dtype=np.int32)), ab.strings([str(x) for x in names]),
        ab.from_numpy(np.array([-1 if p is None else p for p in pos], np.int32), null=missing)],
        schema=SCHEMAS["action_names"])


@dataclass(frozen=True)
class ObservationName:
    """What entry `position` of a step's observation is (table observation_names): a number called
    `name`, or, with `size`, the part (obs // divisor) % size of it; `labels[v]`: the atom value v is read
    from (an index part's)."""
    position: int
    name: str
    divisor: int = 1
    size: int | None = None
    labels: Sequence[str] | None = None


def observation_names_table(names: Sequence[ObservationName]) -> pa.Table:
    n = len(names)
    labels = [list(x.labels) if x.labels is not None else None for x in names]
    flat = [str(v) for x in labels if x is not None for v in x]
    offsets = np.cumsum([0] + [len(x) if x is not None else 0 for x in labels])
    return pa.Table.from_arrays([
        ab.from_numpy(np.array([x.position for x in names], np.int32)), ab.strings([x.name for x in names]),
        ab.from_numpy(np.array([x.divisor for x in names], np.int64)),
        ab.from_numpy(np.array([x.size or 0 for x in names], np.int32),
                      null=np.array([x.size is None for x in names], bool)),
        ab.list_array(offsets, ab.strings(flat), null=np.array([x is None for x in labels], bool)),
    ], schema=SCHEMAS["observation_names"]) if n else None


class AgentTableWriter(Protocol):
    """What AgentRows writes through (TraceWriter)."""

    def write_agent_table(self, table: str, rows: pa.Table) -> None: ...


class AgentRows:
    """Decision and reward-term rows kept until the tracer writes (`write`, before its episode ends)."""

    def __init__(self) -> None:
        self._decisions: list[Decisions] = []
        self._terms: list[RewardTerms] = []

    def decisions(self, rows: Decisions) -> None:
        if len(rows.episode):
            self._decisions.append(rows)

    def reward_terms(self, rows: RewardTerms) -> None:
        if len(rows.episode):
            self._terms.append(rows)

    def write(self, writer: AgentTableWriter) -> None:
        decisions, self._decisions = self._decisions, []
        terms, self._terms = self._terms, []
        if decisions:
            writer.write_agent_table("decisions", Decisions.concat(decisions).table())
        if terms:
            writer.write_agent_table("reward_terms", RewardTerms.concat(terms).table())

