"""What PyReason's rule and fact texts share: spaces do not count (PyReason deletes them), literals
`pred(a)` / `pred(a,b)` with an optional `~` and an optional `:bound` (`[l,u]`, `True`, `False`), and
errors that name the file, line and column of the original text."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from tracelab.engine.errors import RuleSyntaxError
from tracelab.engine.program import SourceLoc

PREDICATE_RE = re.compile(r"[a-zA-Z_][a-zA-Z0-9_.\-]*")  # PyReason's predicate names
COMPONENT_RE = re.compile(r"[a-zA-Z0-9_][a-zA-Z0-9_.@\-]*")  # its variables and node names
OPERATORS = ("<=", ">=", "==", "!=", "<", ">")


@dataclass(frozen=True)
class PLiteral:
    """A PyReason literal with the bound PyReason gives it: `~p(x)` is p(x):[0,0] and `~p(x):[l,u]` is
    p(x):[1-u,1-l] (rounded to 10 digits, as PyReason does)."""
    pred: str
    args: tuple[str, ...]
    lower: float
    upper: float
    column: int  # 1-based, in the original line
    forall: bool = False  # `forall(p(y))` in a rule body
    function: str = ""  # an annotation function in a rule head (`p(x):average`)
    # per argument of a rule head: None, or a head function call `f(x,y)` as (f, (x, y)); args holds its text
    calls: tuple[tuple[str, tuple[str, ...]] | None, ...] = ()


class Squeezed:
    """A text without its white space, remembering each kept character's column in the original line."""

    def __init__(self, text: str, loc: SourceLoc, source_line: str | None = None) -> None:
        kept = [(c, i) for i, c in enumerate(text) if not c.isspace()]
        self.s = "".join(c for c, _ in kept)
        self.cols = [loc.column + i for _, i in kept]
        self.end_col = loc.column + len(text.rstrip())
        self.loc = loc
        self.source_line = source_line if source_line is not None else text

    def col(self, i: int) -> int:
        return self.cols[i] if i < len(self.cols) else self.end_col

    def error(self, i: int, msg: str) -> RuleSyntaxError:
        return RuleSyntaxError(msg, self.loc.file, self.loc.line, self.col(i), self.source_line)


def split_top(sq: Squeezed, start: int, end: int) -> list[tuple[int, int]]:
    """[start, end) of sq.s split at the commas outside () and []: (start, end) of each part."""
    parts, depth, lo = [], 0, start
    for i in range(start, end):
        c = sq.s[i]
        if c in "([":
            depth += 1
        elif c in ")]":
            depth -= 1
            if depth < 0:
                raise sq.error(i, f"unbalanced '{c}'")
        elif c == "," and depth == 0:
            parts.append((lo, i))
            lo = i + 1
    if depth != 0:
        raise sq.error(end, "missing ')' or ']'")
    parts.append((lo, end))
    return parts


def parse_bound(sq: Squeezed, lo: int, hi: int) -> tuple[float, float] | None:
    """`[l,u]`, `True` or `False` (any case) in sq.s[lo:hi]; None if it is none of them (a head may hold
    an annotation function's name there)."""
    text = sq.s[lo:hi]
    if text.lower() == "true":
        return 1.0, 1.0
    if text.lower() == "false":
        return 0.0, 0.0
    if not text.startswith("["):
        return None
    if not text.endswith("]"):
        raise sq.error(hi, "expected ']' at the end of the bound")
    nums = text[1:-1].split(",")
    if len(nums) != 2:
        raise sq.error(lo, f"a bound has two numbers [lower,upper], found {len(nums)}")
    vals = []
    pos = lo + 1
    for which, t in zip(("lower", "upper"), nums):
        try:
            v = float(t)
        except ValueError:
            raise sq.error(pos, f"the {which} bound '{t}' is not a number") from None
        if math.isnan(v) or not 0 <= v <= 1:
            raise sq.error(pos, f"the {which} bound {t} is outside [0,1]")
        vals.append(v)
        pos += len(t) + 1
    if vals[0] > vals[1]:
        raise sq.error(lo, f"the lower bound {nums[0]} is greater than the upper bound {nums[1]}")
    return vals[0], vals[1]


def negate(lower: float, upper: float) -> tuple[float, float]:
    return round(1 - upper, 10), round(1 - lower, 10)


def parse_atom(sq: Squeezed, lo: int, hi: int, what: str, allow_calls: bool = False
               ) -> tuple[str, tuple[str, ...], int, tuple[tuple[str, tuple[str, ...]] | None, ...]]:
    """`pred(a)` or `pred(a,b)` filling sq.s[lo:hi] exactly: (pred, args, index after ')', calls). With
    `allow_calls` (a rule head) an argument may be a head function call `f(x,y)` (PyReason's)."""
    s = sq.s
    op = s.find("(", lo, hi)
    if op < 0:
        raise sq.error(lo, f"expected '(' after the {what} predicate")
    pred = s[lo:op]
    if not PREDICATE_RE.fullmatch(pred):
        raise sq.error(lo, f"'{pred}' is not a predicate name (a letter or '_', then letters, digits, "
                           "'_', '.' and '-')")
    cp = _closing(s, op, hi)
    if cp < 0:
        raise sq.error(hi, f"expected ')' to close the {what} '{pred}('")
    if "(" in s[op + 1:cp] and not allow_calls:
        raise sq.error(s.find("(", op + 1, cp), f"a function call in the arguments of a {what}: head functions "
                                               "are only allowed in a rule head")
    args, calls = [], []
    for a_lo, a_hi in split_top(sq, op + 1, cp):
        a = s[a_lo:a_hi]
        calls.append(_call(sq, a_lo, a_hi) if "(" in a else None)
        if calls[-1] is None and not COMPONENT_RE.fullmatch(a):
            raise sq.error(a_lo, f"'{a}' is not a component name (letters, digits, '_', then also '.', "
                                 "'@' and '-')")
        args.append(a)
    if len(args) > 2:
        raise sq.error(op + 1, f"'{pred}' has {len(args)} arguments: a PyReason literal is on a node (one) "
                               "or an edge (two)")
    return pred, tuple(args), cp + 1, tuple(calls) if any(calls) else ()


def _closing(s: str, op: int, hi: int) -> int:
    """The index of the ')' that closes the '(' at op, or -1."""
    depth = 0
    for i in range(op, hi):
        depth += {"(": 1, ")": -1}.get(s[i], 0)
        if depth == 0:
            return i
    return -1


def _call(sq: Squeezed, lo: int, hi: int) -> tuple[str, tuple[str, ...]]:
    """A head function call `f(x,y)` in sq.s[lo:hi]: (f, (x, y))."""
    s = sq.s
    op = s.find("(", lo, hi)
    name = s[lo:op]
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise sq.error(lo, f"'{name}' is not a head function name")
    if _closing(s, op, hi) != hi - 1 or op + 1 == hi - 1:
        raise sq.error(op, f"expected {name}(arguments) as a head function call")
    args = tuple(s[a:b] for a, b in split_top(sq, op + 1, hi - 1))
    for (a_lo, _), a in zip(split_top(sq, op + 1, hi - 1), args):
        if not COMPONENT_RE.fullmatch(a):
            raise sq.error(a_lo, f"'{a}' is not a component name: a head function's arguments are variables "
                                 "or node names")
    return name, args


def parse_literal(sq: Squeezed, lo: int, hi: int, what: str, *, allow_function: bool = False) -> PLiteral:
    """One literal in sq.s[lo:hi] with its optional `~` and `:bound` (or `:function` in a head)."""
    s = sq.s
    if s.startswith("~~", lo):
        raise sq.error(lo, "double negation '~~' is not allowed")
    neg = s.startswith("~", lo)
    start = lo + 1 if neg else lo
    for op in OPERATORS:
        k = s.find(op, start, hi)
        if k >= 0:
            raise sq.error(k, f"comparison clauses ('{op}') are not supported by tracelab: PyReason added them in "
                              "1.8.11, and since 3.0.0 its grounding skips them (a rule with one fires as the "
                              "rule without it); write the rule without this clause, or the comparison as a "
                              "predicate set by facts (e.g. different(x,y))")
    pred, args, after, calls = parse_atom(sq, start, hi, what, allow_calls=allow_function)
    lower, upper = 1.0, 1.0
    if after < hi:
        if s[after] != ":":
            raise sq.error(after, f"expected ':' and a bound, or the end of the {what}, found '{s[after]}'")
        if after + 1 == hi:
            raise sq.error(hi, "expected a bound after ':'")
        bound = parse_bound(sq, after + 1, hi)
        if bound is None:
            name = s[after + 1:hi]
            if not allow_function:
                raise sq.error(after + 1, f"expected a bound [l,u], True or False after ':', found '{name}'")
            if neg or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
                raise sq.error(after + 1, f"'{name}' is not a bound nor an annotation function name")
            return PLiteral(pred, args, 0.0, 1.0, sq.col(lo), function=name, calls=calls)
        lower, upper = negate(*bound) if neg else bound  # ~p(x):True is p(x):[0,0]
    elif neg:
        lower, upper = 0.0, 0.0
    return PLiteral(pred, args, lower, upper, sq.col(lo), calls=calls)
