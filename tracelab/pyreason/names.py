"""PyReason names as tracelab names. PyReason allows predicates such as `Friends`, `has.part` or `a-b`
and lower-case variables (`x`); tracelab wants predicates `[a-z][A-Za-z0-9_]*`, variables that start with
an upper-case letter and statement names `[A-Za-z_][A-Za-z0-9_-]*`. The mapping is deterministic (first
come, first named) and kept both ways, so that outputs (PyReason's trace CSV) can use the original names."""
from __future__ import annotations

import re

_PRED_OK = re.compile(r"[a-z][A-Za-z0-9_]*")
_NAME_OK = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")
_NOT_WORD = re.compile(r"[^A-Za-z0-9_]")


def _unique(base: str, taken: dict[str, str], original: str) -> str:
    """`base`, or `base_2`, `base_3`, ... : the first not taken by another original name."""
    name, k = base, 1
    while taken.get(name, original) != original:
        k += 1
        name = f"{base}_{k}"
    taken[name] = original
    return name


class NameMap:
    """Predicate names and rule/fact names of one translated program, both ways."""

    def __init__(self) -> None:
        self.pred_to_tl: dict[tuple[str, int], str] = {}  # (PyReason name, arity) -> tracelab name
        self.pred_from_tl: dict[str, str] = {}
        self.stmt_from_tl: dict[str, str] = {}

    def predicate(self, name: str, arity: int = 1) -> str:
        """`Friends` -> `friends`, `has.part` -> `has_part`, `_x` -> `p_x`; a clash adds `_2`. PyReason
        keeps node and edge labels apart: a name used with both arities is two predicates here, the
        arity met second named `<name>_edge` (or `<name>_node`)."""
        got = self.pred_to_tl.get((name, arity))
        if got is not None:
            return got
        base = name
        if not _PRED_OK.fullmatch(base):
            base = _NOT_WORD.sub("_", base)
            base = base[0].lower() + base[1:] if base[0].isupper() else base
            if not base[0].islower():
                base = "p" + base
        if (name, 3 - arity) in self.pred_to_tl:
            base += "_edge" if arity == 2 else "_node"
        got = _unique(base, self.pred_from_tl, name)
        self.pred_to_tl[(name, arity)] = got
        return got

    def predicates_named(self, name: str) -> list[str]:
        """The tracelab predicates of PyReason's `name` (one per arity it is used with), at least one."""
        return [tl for (n, _), tl in self.pred_to_tl.items() if n == name] or [self.predicate(name)]

    def statement(self, name: str) -> str:
        """A new rule or fact name for each call (PyReason allows a name twice, tracelab does not); names
        tracelab cannot write lose the characters it cannot."""
        base = name if _NAME_OK.fullmatch(name) else re.sub(r"[^A-Za-z0-9_-]", "_", name)
        if not base or not (base[0].isalpha() or base[0] == "_"):
            base = "r_" + base
        got, k = base, 1
        while got in self.stmt_from_tl:
            k += 1
            got = f"{base}_{k}"
        self.stmt_from_tl[got] = name
        return got

    def original_predicate(self, tl_name: str) -> str:
        return self.pred_from_tl.get(tl_name, tl_name)

    def original_statement(self, tl_name: str) -> str:
        return self.stmt_from_tl.get(tl_name, tl_name)


def variable_names(components: list[str]) -> dict[str, str]:
    """A rule's PyReason components (all variables: `x`, `y1`, `customer`) -> tracelab variables (`X`,
    `Y1`, `Customer`), distinct within the rule."""
    out: dict[str, str] = {}
    taken: dict[str, str] = {}
    for c in components:
        if c in out:
            continue
        base = _NOT_WORD.sub("_", c)
        base = base[0].upper() + base[1:] if base[0].isalpha() else "V" + base
        out[c] = _unique(base, taken, c)
    return out
