"""tracelab.engine: a temporal annotated-logic engine (generalized annotated programs with delays and
immediate rules), compiled with numba, batched over worlds, with a columnar trace of every change.
The language and its semantics: docs/language.md."""
from .annotations import register_annotation
from .core import STAT_NAMES, TRACE_COLUMNS, Engine
from .errors import (
    FixpointError,
    InconsistencyError,
    ProgramCheckError,
    ProgramError,
    RuleSyntaxError,
)
from .facttable import load_fact_table
from .graph import Graph, load_graphml
from .grounding import GroundingTable
from .kernel import CAUSE_EXTERNAL, CAUSE_FACT, CAUSE_POLICY, CAUSE_RESET, CAUSE_RULE
from .parser import check_program, load_program, parse_literal, parse_program

__all__ = [
    "Engine", "register_annotation", "GroundingTable", "TRACE_COLUMNS", "STAT_NAMES",
    "CAUSE_FACT", "CAUSE_EXTERNAL", "CAUSE_RULE", "CAUSE_POLICY", "CAUSE_RESET",
    "parse_program", "load_program", "parse_literal", "check_program", "load_graphml", "load_fact_table", "Graph",
    "ProgramError", "RuleSyntaxError", "ProgramCheckError", "InconsistencyError", "FixpointError",
]
