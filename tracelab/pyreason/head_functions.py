"""PyReason's head functions as tracelab head functions (engine/head_functions.py).

PyReason calls a user's head function `f(args)` once per rule grounding set: `args` is a numba typed
list, per argument of the call, of the typed list of the node names that argument's variable grounds
to (a component that is not a body variable: its own name), and `f` returns a typed list of node names,
the head's nodes. tracelab grounds tuple by tuple: the engine calls the adapter once per distinct
argument tuple of a grounding, and the adapter hands `f` one-element lists and takes the single node it
returns (docs/pyreason.md, "Head functions")."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any


def engine_name(index: int, fn: Callable[..., Any]) -> str:
    """The name the translation gives PyReason's function `fn` (registered `index`-th)."""
    return f"pyreason_{index}_" + "".join(c if c.isalnum() else "_" for c in fn.__name__.lower())


def adapter(fn: Callable[..., Any]) -> Callable[..., str]:
    """A tracelab head function `(*node_names) -> node_name` calling PyReason's `fn(typed lists)`."""
    import numba

    def call(*names: str) -> str:
        args = numba.typed.List([numba.typed.List([n]) for n in names])
        result = list(fn(args))
        if len(result) != 1 or not isinstance(result[0], str):
            raise ValueError(f"{fn.__name__} returned {result!r} for {list(names)}: tracelab calls a head "
                             "function once per grounding and needs exactly one node name back")
        return result[0]

    return call
