"""`pr.settings`: PyReason's settings with its names, defaults and type checks, and what each one does
here (docs/pyreason.md, "Switching from PyReason", lists them). Settings that change the reasoning
become directives of the translated program or a change of the graph given to the engine; the others
are accepted and do nothing, said below per setting."""
from __future__ import annotations

import os
from dataclasses import replace
from typing import Any

import numpy as np

from tracelab.engine import Graph

# name: (default, what it does here)
SETTINGS: dict[str, tuple[Any, str]] = {
    "verbose": (True, "no-op: the library prints nothing"),
    "output_to_file": (False, "no-op: nothing is printed to redirect"),
    "output_file_name": ("pyreason_output", "no-op (output_to_file)"),
    "graph_attribute_parsing": (True, "False: the graph's attributes give no facts"),
    "abort_on_inconsistency": (False, "no-op, as in PyReason 3.x (which never reads it)"),
    "memory_profile": (False, "no-op"),
    "reverse_digraph": (False, "True: every edge of the graph is reversed, its attributes with it"),
    "atom_trace": (False, "True: the rule trace has the old bounds, names, messages and clause columns"),
    "save_graph_attributes_to_trace": (False, "True: the graph's facts are rows of the rule trace"),
    "canonical": (False, "no-op, as in PyReason 3.x (persistent decides)"),
    "persistent": (False, "False: `%timesteps reset`; True: atoms keep their bounds between steps"),
    "inconsistency_check": (True, "False: `%inconsistency take_new` (the new bound replaces the old)"),
    "static_graph_facts": (True, "False: the graph's facts hold at t = 0 only, not frozen"),
    "store_interpretation_changes": (True, "no-op: the trace is always kept"),
    "parallel_computing": (False, "no-op: one engine, its kernel chosen by tracelab"),
    "update_mode": ("intersection", "'override': `%mode override`; any other str intersects, as in PyReason"),
    "allow_ground_rules": (False, "True: a rule component that names a node is that node (a constant)"),
    "fp_version": (False, "no-op: one engine, the same answers"),
    "tracelab_run": (None, "a directory: each reason() records into this new tracelab run"),
    "tracelab_evaluator": ("auto", "'auto': a small program on the reference evaluator (plain Python, no numba), "
                                   "others on the compiled engine; 'compiled' or 'reference' chooses"),
}
EVALUATORS = ("auto", "compiled", "reference")


class Settings:
    """PyReason's `_Settings`: attributes with its names; an unknown name or a value of the wrong type
    is refused (TypeError / AttributeError, as PyReason's setters do)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        for name, (default, _) in SETTINGS.items():
            object.__setattr__(self, name, default)

    def __setattr__(self, name: str, value: Any) -> None:
        if name not in SETTINGS:
            raise AttributeError(f"pr.settings has no setting {name!r}")
        default = SETTINGS[name][0]
        if isinstance(default, bool) and not isinstance(value, bool):
            raise TypeError(f"pr.settings.{name}: value has to be a bool, got {value!r}")
        if name == "update_mode" and not isinstance(value, str):  # as PyReason: any other str intersects
            raise TypeError(f"pr.settings.update_mode: value has to be a str, got {value!r}")
        if name in ("output_file_name",) and not isinstance(value, str):
            raise TypeError(f"pr.settings.{name}: file_name has to be a string, got {value!r}")
        if name == "tracelab_run" and value is not None and not isinstance(value, (str, os.PathLike)):
            raise TypeError(f"pr.settings.tracelab_run must be a directory path or None, got {value!r}")
        if name == "tracelab_evaluator" and value not in EVALUATORS:
            raise ValueError(f"pr.settings.tracelab_evaluator: one of {', '.join(EVALUATORS)}, got {value!r}")
        object.__setattr__(self, name, value)

    def directives(self) -> list[str]:
        """The translated program's directives these settings ask for (besides persistent)."""
        out = []
        if self.update_mode == "override":  # type: ignore[attr-defined]
            out.append("%mode override  # pr.settings.update_mode")
        if not self.inconsistency_check:  # type: ignore[attr-defined]
            out.append("%inconsistency take_new  # pr.settings.inconsistency_check = False")
        return out

    def graph_for_engine(self, graph: Graph) -> Graph:
        """The loaded graph as these settings give it to the engine."""
        if not self.graph_attribute_parsing:  # type: ignore[attr-defined]
            graph = replace(graph, fact_label=graph.fact_label[:0], fact_args=graph.fact_args[:0],
                            fact_bounds=graph.fact_bounds[:0], fact_window=None, fact_static=None)
        if self.reverse_digraph:  # type: ignore[attr-defined]
            args = graph.fact_args.copy()
            on_edge = args[:, 1] >= 0
            args[on_edge] = args[on_edge][:, ::-1]
            graph = replace(graph, fact_args=np.ascontiguousarray(args),
                            edges=np.ascontiguousarray(graph.edges[:, ::-1]))
        if not self.static_graph_facts:  # type: ignore[attr-defined]
            graph = replace(graph, fact_window=np.zeros((graph.n_facts, 2), np.int64),
                            fact_static=np.zeros(graph.n_facts, np.bool_))
        return graph


def settings_dict(settings: Settings) -> dict[str, Any]:
    """The settings' values (what a recorded run keeps of them)."""
    return {name: (os.fspath(v) if isinstance(v, os.PathLike) else v)
            for name in SETTINGS for v in [getattr(settings, name)]}


__all__ = ["SETTINGS", "Settings", "settings_dict"]
