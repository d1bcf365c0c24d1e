"""What `pr.reason()` returns, read the ways PyReason reads its interpretation: `get_dict()`, `query()`,
`time` (the last timestep reasoned), `fp_cnt` (fixed-point operations), and the rule trace behind
`filter_and_sort_nodes` / `filter_and_sort_edges` and `get_rule_trace` (pandas DataFrames, pandas being
the optional extra `tracelab[pyreason]`). The rows are the engine's trace in PyReason's layout
(trace_csv.PyReasonTrace), so every reading agrees with the CSV files `save_rule_trace` writes."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from tracelab.frozen_imports import import_frozen
from .objects import Interval, Query, _pair
from .trace_csv import PyReasonTrace
from .unsupported import UnsupportedFeature, unsupported


def _pandas() -> Any:
    """pandas, imported by the first DataFrame made (0.5 s of CPU a script without one does not pay)."""
    try:
        return import_frozen("pandas")
    except ImportError:
        raise UnsupportedFeature("PyReason's DataFrames need pandas: pip install 'tracelab[pyreason]'") from None


class Interpretation:
    """The reasoning's final state and its trace (one engine, world 0)."""

    def __init__(self, engine: Any, trace: PyReasonTrace, nodes: Sequence[str], edges: Sequence[tuple[str, str]],
                 time: int, fp_cnt: int, persistent: bool, atom_trace: bool = True) -> None:
        self.engine = engine
        self.trace = trace
        self.nodes = list(nodes)
        self.edges = list(edges)
        self.time = time
        self.fp_cnt = fp_cnt
        self.persistent = persistent
        self.atom_trace = atom_trace  # PyReason's setting when reason() ran: the rule trace's layout

    def _atom(self, pred: str, component: str | tuple[str, ...]) -> int | None:
        """The engine's id of PyReason's pred(component), None if the engine never made it."""
        vocab = self.engine.vocab
        args = (component,) if isinstance(component, str) else tuple(component)
        label = vocab.label_ids.get(self.trace.names.predicate(pred, len(args)))
        nodes = [vocab.node_ids.get(a) for a in args]
        if label is None or any(n is None for n in nodes):
            return None
        return vocab.find(label, tuple(nodes))

    def query(self, query: Query, return_bool: bool = True) -> bool | tuple[float, float]:
        """Whether the atom's final bound lies inside the query's bound; with return_bool=False its bound,
        (0, 1) when the atom was never set and (0, 0) when it lies outside (PyReason's answers)."""
        aid = self._atom(query.get_predicate(), query.get_component())
        if aid is None:
            return False if return_bool else (0, 1)
        bound = self.engine.bound(aid)
        if bound in query.get_bounds():
            return True if return_bool else (float(bound[0]), float(bound[1]))
        return False if return_bool else (0, 0)

    def get_num_ground_atoms(self) -> list[int]:
        raise unsupported("interpretation.get_num_ground_atoms()")

    def get_final_num_ground_atoms(self) -> int:
        raise unsupported("interpretation.get_final_num_ground_atoms()")

    def get_dict(self) -> dict[int, dict[Any, dict[str, tuple[float, float]]]]:
        """{t: {node or edge: {label: (lower, upper)}}} from the trace's rows: a label is there at t when
        it changed at t (and, when persistent, at every later t)."""
        out: dict[int, dict[Any, dict[str, tuple[float, float]]]] = {
            t: {c: {} for c in (*self.nodes, *self.edges)} for t in range(self.time + 1)}
        for rows, bounds in ((self.trace.node_rows, self.trace.node_bounds),
                             (self.trace.edge_rows, self.trace.edge_bounds)):
            for row, bound in zip(rows, bounds):
                t, comp, label = row[0], row[2], row[3]
                for when in range(t, self.time + 1 if self.persistent else t + 1):
                    out[when].setdefault(comp, {})[label] = bound
        return out

    def filter_and_sort(self, edges: bool, labels: Sequence[str], bound: Interval | Sequence[float],
                        sort_by: str, descending: bool) -> list[Any]:
        """PyReason's Filter: per timestep, the components with a change of one of `labels` inside
        `bound` (the last change of each at that t), a column per label ([0,1] where it did not change),
        rows sorted by the new bound's lower or upper end."""
        pd = _pandas()
        window = Interval(*_pair(bound))
        rows, bounds = (self.trace.edge_rows, self.trace.edge_bounds) if edges else \
            (self.trace.node_rows, self.trace.node_bounds)
        latest: dict[tuple[int, Any, str], tuple[float, float]] = {}
        for row, b in zip(rows, bounds):
            latest[(row[0], row[2], row[3])] = b
        key = 0 if sort_by == "lower" else 1
        order = sorted(latest.items(), key=lambda kv: kv[1][key], reverse=descending) \
            if sort_by in ("lower", "upper") else list(latest.items())
        per_time: list[dict[Any, dict[str, list[float]]]] = [{} for _ in range(self.time + 1)]
        for (t, comp, label), b in order:
            if label in labels and b in window and t <= self.time:
                per_time[t].setdefault(comp, {lab: [0, 1] for lab in labels})[label] = [b[0], b[1]]
        return [pd.DataFrame([{"component": c, **v} for c, v in d.items()], columns=["component", *labels])
                for d in per_time]

    def rule_trace(self) -> tuple[Any, Any]:
        """(nodes, edges) DataFrames with PyReason's columns (its layout for the reasoning's atom_trace);
        clause columns hold lists of components."""
        pd = _pandas()
        return tuple(pd.DataFrame(rows, columns=cols)
                     for cols, rows in (self.trace.layout(which, self.atom_trace) for which in ("nodes", "edges")))
