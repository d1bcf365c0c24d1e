"""PyReason's rows for an atom that several facts set in one timestep. PyReason applies a timestep's facts
one by one, each a row of its rule trace: a fact whose bound misses the bound the facts before it left is
a row of its own, not consistent ("Conflicting bounds ... Update from [..] to [..] is not allowed"), and
resets the atom to [0,1], frozen (its committed traces: examples/csv_outputs/inconsistency_example_*,
cybersecurity_rule_trace_*). The engine applies an atom's facts of one pass together: their intersection,
or on an empty one the policy's [0,1] (the same end bound), so one row or, from [0,1], none. This module
rebuilds PyReason's rows from the facts themselves; the trace (trace_csv.py) uses them when their end
bound is the engine's."""
from __future__ import annotations

from dataclasses import dataclass

EPS = 1e-9  # the engine's tolerance for an empty intersection (engine/kernel.py's EPS)


@dataclass(frozen=True)
class StepFact:
    name: str  # `Occurred Due To` of its row
    lower: float
    upper: float
    order: int = 0  # its place among the program's facts (PyReason applies them in that order)
    by: str = "Fact"  # `Triggered By`: "IPL" for the partner a fact's IPL sets (translate.ipl_facts)
    conflict_name: str = ""  # `Occurred Due To` of its conflict row, if not `name` (an IPL partner's: the fact)
    pred: str = ""  # the PyReason predicate whose grounding conflicts (an IPL partner's: the fact's)


@dataclass(frozen=True)
class FactRow:
    old: tuple[float, float]
    new: tuple[float, float]
    name: str
    consistent: bool
    incoming: tuple[float, float]  # the fact's bound (the message quotes it)
    fact: StepFact | None = None


def applied_one_by_one(old: tuple[float, float], facts: list[StepFact]) -> tuple[list[FactRow], tuple[float, float]]:
    """The rows of `facts` applied in order to an atom at `old` (intersection; a conflict resets to [0,1]
    and freezes, so the facts after it are rows of a frozen atom: `on_frozen_atom`), and the atom's bound at
    the end."""
    rows: list[FactRow] = []
    bound = old
    for k, f in enumerate(facts):
        lo, up = max(bound[0], f.lower), min(bound[1], f.upper)
        if lo > up + EPS:
            rows.append(FactRow(bound, (0.0, 1.0), f.conflict_name or f.name, False, (f.lower, f.upper), f))
            return rows + on_frozen_atom(facts[k + 1:]), (0.0, 1.0)
        if (lo, up) != bound:
            rows.append(FactRow(bound, (lo, up), f.name, True, (f.lower, f.upper), f))
            bound = (lo, up)
    return rows, bound


def on_frozen_atom(facts: list[StepFact]) -> list[FactRow]:
    """PyReason's rows of facts applied to a frozen (static) atom: the atom keeps its bound, yet each fact
    is a row with its own bound as old and new (its interpretation.py, "Check if bnd is static": the row
    holds the fact's bound; the committed cybersecurity trace's severity_source_B row). The partner rows a
    fact's IPL sets (`by` "IPL") are not PyReason's here: it writes the partner's bound with the fact."""
    return [FactRow((f.lower, f.upper), (f.lower, f.upper), f.name, True, (f.lower, f.upper), f)
            for f in facts if f.by == "Fact"]


def conflict_message(atom: str, old: tuple[float, float], incoming: tuple[float, float]) -> str:
    """PyReason's message of a same-predicate conflict (its bounds with three decimals)."""
    return (f"Inconsistency occurred. Conflicting bounds for {atom}. Update from [{old[0]:.3f}, {old[1]:.3f}] to "
            f"[{incoming[0]:.3f}, {incoming[1]:.3f}] is not allowed. Setting bounds to [0,1] and static=True for "
            "this timestep.")
