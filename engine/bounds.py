"""An atom's bound tested against a literal's: I ⊨ lit. Its own module, without the program's types, so
that the why searches over a stored run (tracelab/store/model.py) test a clause as the engine does
without loading them (issue 40: a reading command loads only what it uses)."""
from __future__ import annotations

from typing import Protocol

EPS = 1e-9


class BoundedLiteral(Protocol):
    """What the test reads of a literal (program.Literal; the store's Clause): its bound and its `~`."""
    @property
    def lower(self) -> float: ...
    @property
    def upper(self) -> float: ...
    @property
    def negated(self) -> bool: ...


def effective_bound(lower: float, upper: float, negated: bool) -> tuple[float, float]:
    """The interval a literal tests or sets on its atom: `~p:[l,u]` speaks of p as [1-u, 1-l]."""
    return (1.0 - upper, 1.0 - lower) if negated else (lower, upper)


def satisfies(atom_lower: float, atom_upper: float, lit: BoundedLiteral, closed: bool = False) -> bool:
    """I ⊨ lit iff the atom's interval (complemented for `~`) is contained in the literal's bound. On a
    closed predicate (`%closed`) an atom that is [0,1] is read as [0,0]."""
    if closed and atom_lower == 0.0 and atom_upper == 1.0:
        atom_upper = 0.0
    a, b = effective_bound(atom_lower, atom_upper, lit.negated)
    return a >= lit.lower - EPS and b <= lit.upper + EPS
