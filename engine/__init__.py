"""tracelab.engine: a temporal annotated-logic engine (generalized annotated programs with delays and
immediate rules), compiled with numba, batched over worlds, with a columnar trace of every change.
The language and its semantics: docs/language.md.

The files by stage (a program flows down; each boundary is a named type, as Soufflé names its stages):

    language   parser.py -> program.py (the AST), spelling.py and bounds.py (its names and bound test,
               without its types), errors.py, annotations.py, head_functions.py,
               cause_kinds.py (what a trace row's cause_kind means), parse_limit.py (the parser's memory),
               crisp.py (bounds as value codes: which kernel a program gets)
    inputs     graph.py, graphml_scan.py, graphml_expat.py, graphml_raw.py, facttable.py, safe_files.py,
               duckdb_limits.py, terminal_text.py (a stranger's strings made safe to show),
               vocabulary.py (nodes, labels and atoms as dense ids)
    grounding  grounding.py, grounding_limit.py, grounding_cache.py (a build's groundings kept on disk, in
               array_file.py's plain arrays), aggregate_tables.py -> kernel_tables.py (what the kernels read)
    kernels    kernel.py (counting), lanes.py (crisp, 64 worlds a word), restore_kernel.py, trace_take.py,
               codegen.py (kernel.py rewritten for one program)
    backends   backend_api.py (what a backend may touch of the Engine), backend_counting.py, backend_lanes.py,
               backend_compiled.py, compile_cache.py, compile_job.py, compile_background.py, numba_cache.py,
               numba_startup.py, numba_python.py (the kernels as Python before their first compile),
               direct_call.py (the step's compiled call without numba's dispatch), kernel_names.py
    the Engine core.py (builds, steps, traces, snapshots), memory.py, notices.py (what it logs, never prints)
    oracle     reference.py (docs/language.md run naively; the differential tests' other side)

They stay in one flat folder, not a folder per stage: numba keys its disk cache by a function's file,
so moving kernel.py, lanes.py, restore_kernel.py, trace_take.py or graphml_scan.py would make every user's
first run compile them all again, and ~130 files outside engine/ import its modules by name. With 46 files
the stage is already in most names (backend_*, compile_*, graphml_*, grounding*) and in this map;
Soufflé's stage folders each hold dozens.

The names below are imported on first use (PEP 562): importing a light submodule such as
`tracelab.engine.safe_files` (which the store and the CLI use) must not import numba and the kernels."""

import importlib  # no `from __future__ import annotations` here: it would bind the name `annotations`,
                  # which `from . import annotations` (the submodule) would then find instead
from typing import TYPE_CHECKING, Any

# public name -> the submodule that defines it
_EXPORTS = {
    "register_annotation": "annotations",
    "register_head_function": "head_functions", "unregister_head_function": "head_functions",
    "Engine": "core", "STAT_NAMES": "core", "TRACE_COLUMNS": "core",
    "FixpointError": "errors", "InconsistencyError": "errors", "ProgramCheckError": "errors",
    "ProgramError": "errors", "RuleSyntaxError": "errors", "is_interrupt": "errors",
    "load_fact_table": "facttable",
    "Graph": "graph", "load_graphml": "graph",
    "GroundingTable": "grounding",
    "CAUSE_EXTERNAL": "cause_kinds", "CAUSE_FACT": "cause_kinds", "CAUSE_POLICY": "cause_kinds",
    "CAUSE_RESET": "cause_kinds", "CAUSE_RULE": "cause_kinds",
    "check_program": "parser", "load_program": "parser", "parse_literal": "parser", "parse_program": "parser",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


if TYPE_CHECKING:  # for type checkers and editors: the same names, imported eagerly
    from .annotations import register_annotation
    from .head_functions import register_head_function, unregister_head_function
    from .core import STAT_NAMES, TRACE_COLUMNS, Engine
    from .errors import (FixpointError, InconsistencyError, ProgramCheckError, ProgramError, RuleSyntaxError,
                         is_interrupt)
    from .facttable import load_fact_table
    from .graph import Graph, load_graphml
    from .grounding import GroundingTable
    from .cause_kinds import CAUSE_EXTERNAL, CAUSE_FACT, CAUSE_POLICY, CAUSE_RESET, CAUSE_RULE
    from .parser import check_program, load_program, parse_literal, parse_program
