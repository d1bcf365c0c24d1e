"""PyReason programs as they are (docs/pyreason.md): PyReason's rule, fact and GraphML formats read and
translated into tracelab programs, and rule traces written in PyReason's CSV layout.

- rules.py: PyReason's rule text (and its CSV / JSON rule files, with thresholds and rule options);
- facts.py: PyReason's fact text in its CSV / JSON fact files;
- graphml.py: a GraphML file with PyReason's attribute mapping (a number v is [v,1]);
- names.py: PyReason names (predicates, variables, rule names) as tracelab names, and back;
- translate.py: all of it as one tracelab program text, parsed by the engine's parser;
- trace_csv.py: the engine's trace rows as PyReason's rule_trace_nodes / rule_trace_edges CSV files.
"""
from .translate import PyReasonProgram, load_pyreason

__all__ = ["PyReasonProgram", "load_pyreason"]
