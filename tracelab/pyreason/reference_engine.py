"""A small PyReason program reasoned by the reference evaluator (engine/reference.py) instead of the
compiled engine: the hello world spent most of its CPU loading numba and the engine's cached kernels
(docs/benchmarks.md, "PyReason's warm hello world"), where plain Python answers it in milliseconds.

`ReferenceEngine` is the part of engine.Engine a PyReason reasoning reads (trace_csv.PyReasonTrace,
interpretation.Interpretation, api._Reasoning): atoms as the Engine's dense ids (its Vocabulary), the
step's trace rows as its take_trace() columns, the groundings that rows name, the bounds and static
flags of world 0. Which programs it serves: `serves` (tests/test_pyreason_reference.py holds the two
paths' rule traces equal)."""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tracelab.engine.cause_kinds import CAUSE_POLICY, CAUSE_RULE
from tracelab.engine.graph import Graph
from tracelab.engine.program import Program, ordered_nodes
from tracelab.engine.reference import Atom, ReferenceEvaluator
from tracelab.engine.vocabulary import Vocabulary
from tracelab.reasoning_reference import reference_fits

# a reason(timesteps=-1) runs until it converges: steps assumed for the size test
STEPS_UNTIL_CONVERGED = 10


def serves(program: Program, graph: Graph | None, timesteps: int) -> bool:
    """Whether the reference evaluator answers this program quickly and as the engine does: few
    assignments of the rules' variables (reference_fits) and no immediate rules (whose passes the
    evaluator does not report)."""
    steps = timesteps + 1 if timesteps >= 0 else STEPS_UNTIL_CONVERGED
    return (not any(r.immediate for r in program.rules)
            and reference_fits(program, steps, graph.nodes if graph is not None else ()))


@dataclass
class Groundings:
    """The groundings trace rows name (Engine.groundings' `rule` and `body`), made as rows name them."""
    rule: list[int] = field(default_factory=list)
    bodies: list[list[int]] = field(default_factory=list)

    def body(self, g: int) -> list[int]:
        return self.bodies[g]


class ReferenceEngine:
    """World 0 of `program` on `graph`, stepped by the reference evaluator, read as an Engine."""

    kernel = "reference"

    def __init__(self, program: Program, graph: Graph | None) -> None:
        self.program = program
        self.graph = graph if graph is not None else Graph()
        self.rules = program.rules
        nodes, edges = self.graph.nodes, self.graph.edges.tolist()
        self.ref = ReferenceEvaluator(program, nodes, self.graph.facts,
                                      graph_edges=[(nodes[a], nodes[b]) for a, b in edges])
        self.vocab = Vocabulary(ordered_nodes(program, nodes))
        self.groundings = Groundings()
        self._grounding_ids: dict[tuple[int, tuple[str, ...]], int] = {}
        self._passes = 0
        self._changes = 0
        self._rows_from = 0  # the evaluator's changes already taken
        self._steps = 0
        self._static_of: tuple[int, int] | None = None
        self._static = np.zeros((1, 0), np.bool_)

    @property
    def t(self) -> int:
        return self.ref.t

    def fact(self, i: int) -> Any:
        """Fact i in source order: graph facts 0..g-1, then program facts (as Engine.fact)."""
        return self.ref.facts[i]

    # ---- atoms and bounds ----

    def atom(self, pred: str, *args: str) -> int:
        return self.vocab.atom_by_name(pred, tuple(args))

    def _id(self, atom: Atom) -> int:
        return self.vocab.atom_by_name(atom[0], atom[1])

    def _parts(self, aid: int) -> Atom:
        return self.vocab.atom_parts(aid)

    def bound(self, aid: int, world: int = 0) -> tuple[float, float]:
        return self.ref.bound(self._parts(aid)) if aid < self.vocab.n_atoms else (0.0, 1.0)

    @property
    def lower(self) -> np.ndarray:
        return np.array([[self.bound(a)[0] for a in range(self.vocab.n_atoms)]])

    @property
    def upper(self) -> np.ndarray:
        return np.array([[self.bound(a)[1] for a in range(self.vocab.n_atoms)]])

    @property
    def static(self) -> np.ndarray:
        """[1, atoms]: the static flags, built once per step and atom count (the trace reads them per atom)."""
        key = (self._steps, self.vocab.n_atoms)
        if self._static_of != key:
            self._static = np.array([[self.ref.is_static(self._parts(a)) for a in range(self.vocab.n_atoms)]],
                                    np.bool_)
            self._static_of = key
        return self._static

    @property
    def stats(self) -> dict[str, np.ndarray]:
        return {"passes": np.array([self._passes]), "changes": np.array([self._changes])}

    def pending(self, world: int = 0) -> list[tuple[int, int]]:
        """Scheduled firings of delayed rules, as (due time, -1): the evaluator keeps no grounding ids."""
        return [(t, -1) for t, firings in self.ref._scheduled.items() for _ in firings if t >= self.ref.t]

    # ---- facts in, steps, rows out ----

    def next_external_id(self) -> int:
        return len(self.ref._externals)

    def add_fact(self, aid: int, lower: float = 1.0, upper: float = 1.0, static: bool = False) -> None:
        """An external fact, applied at pass 0 of the next step."""
        pred, args = self._parts(aid)
        self.ref.add_fact(pred, args, lower, upper, static)

    def step(self) -> None:
        self.ref.step()
        self._steps += 1
        new = self.ref.changes[self._rows_from:]
        for c in new:  # the atoms the step set, interned as the rows name them
            self._id(c.atom)
        for atom in self.ref._static:
            self._id(atom)
        self._changes += len(new)
        # the passes of the step, as the engine counts them: up to the first ordinary pass that changed
        # nothing (immediate rules, whose rows could fall in that pass, are not served: `serves`)
        self._passes += 1 + max((c.pass_no for c in new), default=0)

    def take_trace(self) -> dict[str, np.ndarray]:
        """The rows since the last call, as Engine.take_trace()'s columns (world 0)."""
        rows = self.ref.changes[self._rows_from:]
        self._rows_from = len(self.ref.changes)
        grounding = [self._grounding(c.grounding_rule, c.grounding) if c.cause_kind in (CAUSE_RULE, CAUSE_POLICY)
                     else -1 for c in rows]
        ints = {"world": [0] * len(rows), "t": [c.t for c in rows], "pass_no": [c.pass_no for c in rows],
                "atom": [self._id(c.atom) for c in rows], "cause_kind": [c.cause_kind for c in rows],
                "cause_id": [c.cause_id for c in rows], "grounding": grounding,
                "n_sources": [c.n_sources for c in rows]}
        floats = {"old_lower": [c.old[0] for c in rows], "old_upper": [c.old[1] for c in rows],
                  "new_lower": [c.new[0] for c in rows], "new_upper": [c.new[1] for c in rows]}
        return {**{k: np.array(v, np.int64) for k, v in ints.items()},
                **{k: np.array(v, np.float64) for k, v in floats.items()}}

    def _grounding(self, rule: int | None, values: Sequence[str] | None) -> int:
        """The id of rule `rule`'s grounding with these variable values (-1 for none), its body's atoms
        as the engine lists them: each clause's atom, in clause order."""
        if rule is None or values is None:
            return -1
        key = (rule, tuple(values))
        g = self._grounding_ids.get(key)
        if g is None:
            r = self.rules[rule]
            binding = dict(zip(r.variables, values))
            body = [self._id(self.ref._ground(lit, binding)) for lit in r.body]
            g = self._grounding_ids[key] = len(self.groundings.rule)
            self.groundings.rule.append(rule)
            self.groundings.bodies.append(body)
        return g


class ReferenceEpisode:
    """EpisodeRun's stepping (tracelab/reasoning.py) for a ReferenceEngine: nothing recorded."""

    def __init__(self, engine: ReferenceEngine) -> None:
        self.engine = engine

    def steps(self, steps: int, rows_each_step: bool = True) -> Iterator[tuple[int, dict[str, np.ndarray]]]:
        for k in range(steps):
            self.engine.step()
            yield k, self.engine.take_trace()

    def finish(self) -> str:
        return "stopped"
