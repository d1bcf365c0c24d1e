"""PyReason programs as they are (docs/pyreason.md): PyReason's Python API (`import tracelab.pyreason as
pr`), its rule, fact and GraphML formats read and translated into tracelab programs, and rule traces
written in PyReason's CSV layout.

- api.py: PyReason's module-level functions (load_graphml, add_rule, add_fact, reason, ...);
- settings.py: `pr.settings`, each setting's meaning here;
- objects.py: Rule, Fact, Query, Threshold, closed (PyReason's constructors);
- interpretation.py: what reason() returns (get_dict, query, the DataFrames);
- ruleset_filter.py: the rules a query needs (reason(queries=...));
- classifier.py: LogicIntegratedClassifier (a torch model's outputs as facts; imports torch when used);
- temporal_classifier.py: TemporalLogicIntegratedClassifier (the same, polled from a thread on a clock);
- numba_interval.py: PyReason's annotation functions (closed(), the adapter);
- reference_engine.py: a small program reasoned by the reference evaluator (no numba), read as the Engine;
- unsupported.py: UnsupportedFeature, the error of what tracelab does not have;
- rules.py: PyReason's rule text (and its CSV / JSON rule files, with thresholds and rule options);
- facts.py: PyReason's fact text in its CSV / JSON fact files;
- graphml.py: a GraphML file (or a networkx graph) with PyReason's attribute mapping (a number v is [v,1]);
- names.py: PyReason names (predicates, variables, rule names) as tracelab names, and back;
- translate.py: all of it as one tracelab program text, parsed by the engine's parser;
- trace_csv.py: the engine's trace rows as PyReason's rule_trace_nodes / rule_trace_edges rows;
- fact_sequence.py: PyReason's rows of an atom several facts set in one timestep (one by one);
- files.py: what the rule and fact files share (CSV rows, JSON items, PyReason's raise_errors contract);
- as_pyreason.py, __main__.py: `python -m tracelab.pyreason SCRIPT.py`, a PyReason script run unchanged.
"""
import gc

from . import ruleset_filter
from .api import (
    _Settings,
    add_annotation_function,
    add_closed_world_predicate,
    add_fact,
    add_fact_from_csv,
    add_fact_from_json,
    add_head_function,
    add_inconsistent_predicate,
    add_rule,
    add_rule_from_csv,
    add_rule_from_json,
    add_rules_from_file,
    filter_and_sort_edges,
    filter_and_sort_nodes,
    get_interpretation,
    get_rule_trace,
    get_rules,
    get_time,
    load_graph,
    load_graphml,
    load_inconsistent_predicate_list,
    reason,
    record,
    reset,
    reset_rules,
    reset_settings,
    save_rule_trace,
    settings,
)
from .interpretation import Interpretation
from .objects import Fact, Query, Rule, Threshold, closed
from .translate import PyReasonProgram, load_pyreason
from .unsupported import UnsupportedFeature

# numba and pandas are not loaded here: a small program reasons on the reference evaluator, and pandas
# is imported when a DataFrame is made (tests/test_pyreason_imports.py)
gc.freeze()   # the modules loaded so far: no collection traverses them (tracelab/frozen_imports.py)

__all__ = [
    "Fact", "Interpretation", "LogicIntegratedClassifier", "TemporalLogicIntegratedClassifier", "_Settings", "ModelInterfaceOptions", "PyReasonProgram", "Query",
    "Rule", "Threshold", "UnsupportedFeature", "add_annotation_function", "add_closed_world_predicate",
    "add_fact", "add_fact_from_csv", "add_fact_from_json", "add_head_function", "add_inconsistent_predicate",
    "add_rule", "add_rule_from_csv", "add_rule_from_json", "add_rules_from_file", "closed",
    "filter_and_sort_edges", "filter_and_sort_nodes", "get_interpretation", "get_rule_trace", "get_rules",
    "get_time", "load_graph", "load_graphml", "load_inconsistent_predicate_list", "load_pyreason", "reason",
    "record", "reset", "reset_rules", "reset_settings", "ruleset_filter", "save_rule_trace", "settings",
]


def __getattr__(name: str) -> object:
    """The classifier integration imports torch: only when a script asks for it."""
    if name in ("LogicIntegratedClassifier", "ModelInterfaceOptions"):
        from . import classifier
        return getattr(classifier, name)
    if name == "TemporalLogicIntegratedClassifier":
        from . import temporal_classifier
        return temporal_classifier.TemporalLogicIntegratedClassifier
    raise AttributeError(f"module 'tracelab.pyreason' has no attribute {name!r}")
