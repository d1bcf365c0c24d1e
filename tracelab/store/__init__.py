"""The trace store: runs written as Parquet parts while they happen, read live or sealed through DuckDB
views (docs/store.md).

The names below are imported on first use (PEP 562), not with the package: a process that only writes
a run (`tracelab play --run`, TraceWriter) would otherwise load DuckDB with the reader, ~10 MB of its
library resident and more in its catalog, for nothing (docs/benchmarks/history.md, "Memory of long runs")."""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tracelab.store.meta import RunMeta
    from tracelab.store.reader import RunInfo, open_run, query_readonly, retrying, run_info
    from tracelab.store.seal import seal_run
    from tracelab.store.writer import TraceWriter

_HOMES = {"TraceWriter": "writer", "RunMeta": "meta", "open_run": "reader", "run_info": "reader",
          "RunInfo": "reader", "query_readonly": "reader", "retrying": "reader", "seal_run": "seal"}

__all__ = ["TraceWriter", "RunMeta", "open_run", "run_info", "RunInfo", "query_readonly", "retrying",
           "seal_run"]


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'tracelab.store' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"tracelab.store.{home}"), name)
    globals()[name] = value  # the next look-up is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_HOMES])
