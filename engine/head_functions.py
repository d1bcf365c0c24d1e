"""Head functions: a rule head argument computed from the grounding, `processed(first(X)) <-0 ...`
(docs/language.md, "Head functions"). A function is registered from Python by name and maps node names
to a node name. It is called while grounding (engine/grounding.py) and by the reference evaluator, so
every kernel reads the computed head atom from the grounding table like any other head."""
from __future__ import annotations

import inspect
from collections.abc import Callable

from .program import PREDICATE_RE, Term

HeadFunction = Callable[..., str]

_registered: dict[str, tuple[HeadFunction, int | None]] = {}  # name -> (function, arity; None: any)


def register_head_function(name: str, fn: HeadFunction, arity: int | None = None) -> None:
    """Make `fn` usable as the head function `name` in rules parsed from now on: `fn(*node_names) -> str`,
    a pure function (it is called once per distinct argument tuple). `arity`: its number of arguments,
    by default read from its signature (None when it takes `*args`)."""
    if not PREDICATE_RE.fullmatch(name):
        raise ValueError(f"head function name {name!r}: it must start with a lower-case letter and contain "
                         "letters, digits and '_'")
    if not callable(fn):
        raise TypeError(f"head function {name!r} must be callable, got {type(fn).__name__}")
    _registered[name] = (fn, _arity(fn) if arity is None else arity)


def unregister_head_function(name: str) -> None:
    _registered.pop(name, None)


def _arity(fn: HeadFunction) -> int | None:
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):  # a builtin or a compiled function without a signature: any arity
        return None
    if any(p.kind is p.VAR_POSITIONAL for p in params):
        return None
    return sum(1 for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
               and p.default is p.empty)


def check_call(term: Term) -> str | None:
    """Why the call `term` cannot be made (an unknown function, a wrong number of arguments), or None."""
    entry = _registered.get(term.function or "")
    if entry is None:
        known = ", ".join(sorted(_registered)) or "none"
        return (f"unknown head function '{term.function}' (registered: {known}; register it with "
                "tracelab.engine.register_head_function before parsing)")
    arity = entry[1]
    if arity is not None and arity != len(term.call_args):
        return (f"head function '{term.function}' takes {arity} argument{'s' if arity != 1 else ''}, "
                f"given {len(term.call_args)}")
    return None


def bind(term: Term) -> HeadFunction:
    """The function a call names (checked by the parser: KeyError only for a program built by hand)."""
    return _registered[term.function or ""][0]


class HeadFunctionError(ValueError):
    """A head function failed or returned something that is not a node name; the message names both."""


def call(fn: HeadFunction, term: Term, args: tuple[str, ...], rule: str) -> str:
    """fn(*args), checked to be a node name (a str)."""
    try:
        res = fn(*args)
    except Exception as e:  # the user's function: its failure is the rule's, named
        raise HeadFunctionError(f"head function '{term.function}' (rule {rule}) raised {type(e).__name__} "
                                f"for {', '.join(args)}: {e}") from None
    if not isinstance(res, str) or not res:
        raise HeadFunctionError(f"head function '{term.function}' (rule {rule}) returned {res!r} for "
                                f"{', '.join(args)}: a head function returns a node name (a non-empty str)")
    return res
