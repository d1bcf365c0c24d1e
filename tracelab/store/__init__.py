"""The trace store: runs written as Parquet parts while they happen, read live or sealed through DuckDB
views (docs/store.md)."""
from tracelab.store.meta import RunMeta
from tracelab.store.reader import RunInfo, open_run, query_readonly, retrying, run_info
from tracelab.store.seal import seal_run
from tracelab.store.writer import TraceWriter

__all__ = ["TraceWriter", "RunMeta", "open_run", "run_info", "RunInfo", "query_readonly", "retrying",
           "seal_run"]
