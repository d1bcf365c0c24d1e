"""A small program reasoned by the reference evaluator (engine/reference.py), not the compiled engine.

`tracelab reason` on a five-line program spent most of its time loading numba and the engine's cached
kernels (about 1.3 s of CPU of 1.9, docs/benchmarks/history.md "Interactive speed"); the reference evaluator,
plain Python over the same semantics (tests/test_engine_vs_reference.py holds the two equal), answers such
a program in milliseconds. It tries every assignment of a rule's variables over every node each pass, so it
serves only programs whose assignments stay few (REFERENCE_MAX_ASSIGNMENTS); anything else, and anything it
cannot finish (no fixpoint, an inconsistency), runs on the compiled engine, which says why in its own words.
The trace rows come out as the engine's (same text, same order within a pass for the programs in
rules/examples: tests/test_reason_reference.py)."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from tracelab.engine.program import INCONSISTENCY_POLICIES, Program, constant_text, ordered_nodes
from tracelab.engine.reference import CAUSE_FACT, CAUSE_POLICY, CAUSE_RULE, ReferenceEvaluator, atom_text

# rules x nodes ** variables x steps at most: a few thousand evaluations of a body per pass in plain Python
REFERENCE_MAX_ASSIGNMENTS = 50_000
CAUSE_NAMES = {1: "external", 4: "reset"}  # the engine's names (Engine.cause_name) of causes without an id


def reference_fits(program: Program, steps: int, graph_nodes: Sequence[str] = ()) -> bool:
    """Whether the reference evaluator answers this program over `steps` steps quickly (see the module),
    on a graph of these nodes."""
    nodes = max(1, len(ordered_nodes(program, list(graph_nodes))))
    return steps * sum(nodes ** len(r.variables) for r in program.rules) <= REFERENCE_MAX_ASSIGNMENTS


def reference_reasoning(program: Program, steps: int) -> tuple[list[list[dict[str, Any]]],
                                                                 dict[str, tuple[float, float]]]:
    """Each step's trace rows (as `tracelab reason` prints them: t, pass, atom, old, new, cause,
    grounding) and the final interpretation by atom text. Raises what the evaluator raises."""
    ref = ReferenceEvaluator(program)
    rows: list[list[dict[str, Any]]] = []
    for _ in range(steps):
        start = len(ref.changes)
        ref.step()
        rows.append([_row(program, c, atom_text) for c in ref.changes[start:]])
    return rows, {atom_text(a): iv for a, iv in ref.interpretation().items()}


def _row(program: Program, c: Any, atom_text: Any) -> dict[str, Any]:
    return {"t": c.t, "pass": c.pass_no, "atom": atom_text(c.atom), "old": list(c.old), "new": list(c.new),
            "cause": _cause(program, c.cause_kind, c.cause_id),
            "grounding": _grounding(program, c.grounding_rule, c.grounding)}


def _cause(program: Program, kind: int, cid: int) -> str:
    """Engine.cause_name's text for a reference row's cause."""
    if kind == CAUSE_RULE:
        return program.rules[cid].name
    if kind == CAUSE_FACT:
        return f"fact:{program.facts[cid].name}"
    if kind == CAUSE_POLICY:
        return f"policy:{INCONSISTENCY_POLICIES[cid]}"
    return CAUSE_NAMES.get(kind, "reset")


def _grounding(program: Program, rule: int | None, values: Sequence[str] | None) -> str:
    """Engine.grounding_text's text: "X=a, Y=b" ("" for none)."""
    if rule is None or values is None:
        return ""
    return ", ".join(f"{v}={constant_text(x)}" for v, x in zip(program.rules[rule].variables, values))
