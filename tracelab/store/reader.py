"""Open a run for reading, live or sealed, as an in-memory DuckDB connection with the store's views.

Live run (a directory of Parquet parts): raw.<table> are views over read_parquet() of the files the run's
manifest lists (tracelab.store.parts), held in DuckDB variables that LiveRunConnection brings up to date
before every statement; so one connection sees every flush as it lands, all tables at the same moment,
and nothing locks the writer out. A query running longer than the writer's grace period (30 s) after a
compaction can fail with "file not found" (never return wrong rows): long-lived readers run queries
through retrying().
Sealed run (run.duckdb, or any lone .duckdb file): the file is attached READ_ONLY and raw.<table> are
views over its tables. Either way the user-facing views (tracelab.store.schema.VIEWS_SQL) are the same."""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import duckdb
import pyarrow as pa

from tracelab.store import layout
from tracelab.store.meta import effective_status, meta_table, read_meta
from tracelab.store.parts import read_manifest
from tracelab.store.schema import TABLES, VIEWS_SQL

RUNS_DIR = Path("runs")
READONLY_STATEMENTS = {duckdb.StatementType.SELECT, duckdb.StatementType.EXPLAIN}


@dataclass
class RunInfo:
    path: Path          # the run directory, or the lone .duckdb file
    sealed_file: Path | None
    meta: dict[str, Any]
    status: str         # running | finished | failed | interrupted | crashed


def resolve_run(run: str | Path) -> Path:
    """A run given as a path, or as a name under ./runs/."""
    p = Path(run)
    if p.exists():
        return p
    if not p.is_absolute() and (RUNS_DIR / p).exists():
        return RUNS_DIR / p
    raise FileNotFoundError(f"no run {str(run)!r}: not a path, and not a run name under {str(RUNS_DIR)}/")


def _sql_str(s: str | Path) -> str:
    return "'" + str(s).replace("'", "''") + "'"


def _sealed_file(p: Path) -> Path | None:
    if p.is_file():
        return p
    s = layout.sealed_path(p)
    return s if s.exists() else None


def run_info(run: str | Path) -> RunInfo:
    p = resolve_run(run)
    sealed = _sealed_file(p)
    if sealed is not None and not p.is_dir():
        con = duckdb.connect(str(sealed), read_only=True)
        try:
            row = con.execute("SELECT * FROM raw.run").fetchone()
            cols = [d[0] for d in con.description]
        finally:
            con.close()
        meta = dict(zip(cols, row))
        return RunInfo(p, sealed, meta, str(meta.get("status")))
    meta = read_meta(p)
    return RunInfo(p, sealed, meta, effective_status(meta))


def _parts_variable(table: str) -> str:
    return f"tracelab_parts_{table}"


class LiveRunConnection:
    """A DuckDB connection on a run being written. Before each statement it re-reads the run's manifest
    and, if it changed, points every raw.<table> view at the parts it lists (DuckDB variables read by the
    views); everything else is the DuckDB connection's own API."""

    def __init__(self, con: duckdb.DuckDBPyConnection, run_dir: Path) -> None:
        self._con = con
        self._manifest = layout.manifest_path(run_dir)
        self._seen = b""
        self.refresh()

    def refresh(self) -> None:
        """Bring the views up to the manifest's latest flush (cheap when nothing changed)."""
        raw = self._manifest.read_bytes()
        if raw == self._seen:
            return
        for table, files in read_manifest(self._manifest.parent.parent).items():
            self._con.execute(f"SET VARIABLE {_parts_variable(table)} = ?", [[str(f) for f in files]])
        self._seen = raw

    def execute(self, query: Any, parameters: Any = None) -> duckdb.DuckDBPyConnection:
        self.refresh()
        return self._con.execute(query, parameters)

    def sql(self, query: str, **options: Any) -> duckdb.DuckDBPyRelation:
        self.refresh()
        return self._con.sql(query, **options)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._con, name)


RunConnection = duckdb.DuckDBPyConnection | LiveRunConnection


def open_run(run: str | Path) -> RunConnection:
    """A DuckDB connection on the run with the views changes, firings, episodes, steps, metrics, rules,
    facts, atoms, groundings, run (and raw.* underneath). Works on a run being written: then every
    statement sees the latest flush."""
    info = run_info(run)
    con = duckdb.connect(":memory:")
    try:
        con.execute("CREATE SCHEMA raw")
        if info.sealed_file is not None:
            con.execute(f"ATTACH {_sql_str(info.sealed_file.resolve())} AS store (READ_ONLY)")
            for t in (*TABLES, "run"):
                con.execute(f"CREATE VIEW raw.{t} AS SELECT * FROM store.raw.{t}")
            con.execute(VIEWS_SQL)
            return con
        live = LiveRunConnection(con, info.path.resolve())  # sets the variables the views read
        for t in TABLES:
            con.execute(f"CREATE VIEW raw.{t} AS SELECT * FROM read_parquet(getvariable("
                        f"{_sql_str(_parts_variable(t))}))")
        _create_table(con, "raw.run", meta_table(info.meta, info.status))
        con.execute(VIEWS_SQL)
    except BaseException:
        con.close()
        raise
    return live


def _create_table(con: duckdb.DuckDBPyConnection, name: str, table: Any) -> None:
    con.register("_tracelab_tmp", table)
    try:
        con.execute(f"CREATE TABLE {name} AS SELECT * FROM _tracelab_tmp")
    finally:
        con.unregister("_tracelab_tmp")


def query_readonly(con: RunConnection, sql: str,
                   params: dict[str, Any] | None = None) -> duckdb.DuckDBPyRelation:
    """One read-only statement (SELECT, including DESCRIBE/SHOW/SUMMARIZE, or EXPLAIN) as a lazy relation.
    Raises duckdb errors as they come (their text shows the position in the query) and ValueError for a
    statement that could change something."""
    statements = con.extract_statements(sql)
    if len(statements) != 1:
        raise ValueError(f"expected one SQL statement, got {len(statements)}")
    kind = statements[0].type
    if kind not in READONLY_STATEMENTS:
        raise ValueError(f"only read-only queries are allowed (SELECT, EXPLAIN); this is a "
                         f"{kind.name} statement")
    try:
        return con.sql(sql, params=params or None)
    except duckdb.Error:
        # the relation API drops the "LINE 1: ... ^" pointer; binding again through execute() (it fails
        # at the same place, before running anything) raises the error with it
        con.execute(sql, params or None)
        raise


def fetch_arrow(rel: duckdb.DuckDBPyRelation, limit: int | None = None, offset: int = 0) -> pa.Table:
    """The rows [offset, offset+limit) of a relation as an Arrow table, streaming: rows past the limit
    are never materialised."""
    reader = rel.to_arrow_reader(65_536)
    want = None if limit is None else offset + limit
    batches, have = [], 0
    for batch in reader:
        batches.append(batch)
        have += batch.num_rows
        if want is not None and have >= want:
            break
    return pa.Table.from_batches(batches, schema=reader.schema).slice(offset, limit)


T = TypeVar("T")


def retrying(fn: Callable[[], T], attempts: int = 4) -> T:
    """fn(), run again (up to `attempts` times) if it failed because a live run's compaction removed a
    part a long query was still to open."""
    for i in range(attempts):
        try:
            return fn()
        except duckdb.IOException as e:
            if "No such file" not in str(e) or i == attempts - 1:
                raise
            time.sleep(0.01 * (i + 1))
    raise AssertionError("unreachable")
