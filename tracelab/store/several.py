"""Several runs on one sandboxed connection: `tracelab sql RUN RUN ... "SELECT run, ..."`, a folder of
runs, saved queries across runs (docs/store.md, "Several runs").

Each run gets an in-memory catalog of its own, `run_N` (N its place in the list, from 1), holding its
raw.<table> views and the store's views, built exactly as open_run builds them for one run
(reader.create_live_raw_views / sealed_raw_views_sql, schema.VIEWS_SQL). A DuckDB view binds the names
in its text in its own catalog, so run_2.main.changes reads run_2.raw.* and run_2.main.atoms. The
connection's own views (changes, firings, ..., run, and raw.<table>) are the union of every run's, with a
first column `run`: the run's name (run_names).

The sandbox is the one a single run gets (tracelab.store.sandbox): every sealed file is attached (after
the check for a write-ahead log) before external access is switched off, `allowed_directories` lists the
live runs' parts/ folders and nothing else, and the configuration is locked once the views exist; each
sealed file's catalog is checked before anything in it is read, each live run's manifest and folders
as open_run checks them. A live run that gets sealed while the connection is open makes it rebuild
itself on the next statement (a connection attaches nothing once locked down)."""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import duckdb

from tracelab.store import layout
from tracelab.store.catalog import find_runs, is_run
from tracelab.store.kind import can_read
from tracelab.store.reader import (
    BATCH_ROWS,
    LiveParts,
    RefreshingConnection,
    _refusing,
    _sliced,
    _sql_str,
    attach_sealed_file,
    check_live_run,
    check_run_rows,
    create_live_raw_views,
    query_readonly,
    resolve_run,
    sealed_file_of_run,
    sealed_raw_views_sql,
)
from tracelab.store.sandbox import lock_configuration, lock_down, refusal, sandbox_connection
from tracelab.store.schema import STORED_COLUMNS, TABLES, VIEW_NAMES, VIEWS_SQL
from tracelab.store.sealed_catalog import entries_checked, read_sealed_catalogs

if TYPE_CHECKING:  # loaded by each_run_stream only: a SQL query over several runs needs no pyarrow
    import pyarrow as pa

RUN_COLUMN = "run"
# Runs one connection reads at most: each adds its views to the connection (about 0.25 s to open and 3 MB,
# docs/benchmarks.md), so a folder of many thousands would take the command minutes and gigabytes.
# More runs than this: an engine over their Parquet parts (docs/store.md).
MAX_RUNS = 256
DEFAULT_CATALOG = "memory"   # DuckDB's name for an in-memory connection's own database


def expand_runs(given: Sequence[str | Path]) -> tuple[list[Path], bool]:
    """The runs the user named: each a run (a path, or a name under runs/) or a folder, whose runs
    directly inside it are taken (sorted by path); no run twice. Also says whether a folder of runs was
    given (its runs read as several runs even if it holds one). FileNotFoundError names a path that does
    not exist; a path that is neither a run nor holds any is kept, and opening it says what it is."""
    paths: list[Path] = []
    folder = False
    for item in given:
        p = resolve_run(item)
        inside = [] if is_run(p) or not p.is_dir() else find_runs([p])
        folder = folder or bool(inside)
        paths.extend(inside or [p])
    unique: dict[Path, Path] = {}
    for p in paths:
        unique.setdefault(p.resolve(), p)
    return list(unique.values()), folder


def run_names(paths: Sequence[Path]) -> list[str]:
    """Each run's name in the `run` column: its folder's name (a lone .duckdb file's name without the
    suffix; a run's own run.duckdb, named by itself, its folder's name), and for runs that share that
    name, as many of the folders above it as tell them apart (`a/seed-1`, `b/seed-1`)."""
    folders = [p.parent if p.is_file() and p.name == layout.SEALED else p for p in paths]
    parts = [list(p.absolute().parts[:-1]) + [p.stem if p.is_file() else p.name] for p in folders]
    depth = [1] * len(paths)
    while True:
        names = ["/".join(ps[-d:]) for ps, d in zip(parts, depth)]
        clashing = [i for i, n in enumerate(names) if names.count(n) > 1 and depth[i] < len(parts[i])]
        if not clashing:
            return names
        for i in clashing:
            depth[i] += 1


class SeveralRunsConnection(RefreshingConnection):
    """A sandboxed DuckDB connection on several runs (see the module's doc). Before each statement each
    live run's views are brought up to its latest flush and status (reader.LiveParts); everything else is
    the DuckDB connection's own API."""

    def __init__(self, runs: Sequence[Path], names: Sequence[str], union_views: bool = True,
                 raw_tables: Sequence[str] | None = None) -> None:
        """`union_views`: False for a caller of its own SQL that reads each run's raw.* (`raw_tables`: of
        these tables only, and run) as run_N.raw.<table> (catalog_of), or one run's at a time (use):
        neither the union views nor each run's user-facing views are built (15 views a run)."""
        self.runs = list(runs)
        self.names = list(names)
        self._union_views = union_views
        self._raw_tables = tuple(STORED_COLUMNS) if raw_tables is None else tuple(raw_tables)
        self._using: int | None = None    # the run whose own views unqualified names read (use)
        self._con, self._live = _build(self.runs, union_views, self._raw_tables)

    def refresh(self) -> None:
        for live in self._live:
            if not live.update(ready=True):   # sealed meanwhile: attach its file on a new connection
                old, (self._con, self._live) = self._con, _build(self.runs, self._union_views, self._raw_tables)
                old.close()
                if self._using is not None:
                    self._con.execute(f"USE {catalog_of(self._using)}")
                return

    def use(self, index: int | None) -> None:
        """Unqualified names read run `index`'s own views (no `run` column: a saved query written for one
        run), or the union of every run's again (None)."""
        self._using = index
        self._con.execute(f"USE {DEFAULT_CATALOG if index is None else catalog_of(index)}")


def catalog_of(index: int) -> str:
    """The catalog of run `index`'s own views: its raw.<table> are catalog_of(index).raw.<table>."""
    return f"run_{index + 1}"


def _build(runs: Sequence[Path], union_views: bool = True, raw_tables: Sequence[str] = tuple(STORED_COLUMNS),
           ) -> tuple[duckdb.DuckDBPyConnection, list[LiveParts]]:
    if len(runs) > MAX_RUNS:
        raise ValueError(f"{len(runs)} runs given ({runs[0]} ... {runs[-1]}): tracelab reads at most {MAX_RUNS} "
                         "at once; read more through their Parquet parts (docs/store.md, \"The Parquet parts\")")
    con = sandbox_connection()
    try:
        sealed = [sealed_file_of_run(p) for p in runs]
        allowed, identities = [], {}
        # each run's own catalog for its views, all in one statement
        con.execute(";\n".join(f"ATTACH ':memory:' AS {catalog_of(i)}; CREATE SCHEMA {catalog_of(i)}.raw"
                                for i in range(len(runs))))
        for i, (p, s) in enumerate(zip(runs, sealed)):
            if s is not None:
                identities[f"store_{i + 1}"] = attach_sealed_file(con, s, f"store_{i + 1}")
            else:
                allowed.append(check_live_run(p))
        lock_down(con, allowed)
        # every attached file's catalog read in one pass (each still checked before anything of it is read)
        catalogs = read_sealed_catalogs(con, list(identities),
                                        [d for d, identity in identities.items() if entries_checked(identity)])
        live = []
        sealed_views = [sealed_raw_views_sql(con, s, f"store_{i + 1}", f"{catalog_of(i)}.raw",
                                             catalogs[f"store_{i + 1}"], raw_tables, identities[f"store_{i + 1}"])
                        for i, s in enumerate(sealed) if s is not None]
        if sealed_views:  # every sealed run's views in one statement, their raw.run rows checked in one
            con.execute(";\n".join(sealed_views))
            check_run_rows(con, [(s, f"{catalog_of(i)}.raw") for i, s in enumerate(sealed) if s is not None])
        for i, (p, s) in enumerate(zip(runs, sealed)):
            raw = f"{catalog_of(i)}.raw"
            if s is None:
                parts = LiveParts(con, p.resolve(), raw, prefix=f"{i + 1}_")
                parts.update(ready=False)
                create_live_raw_views(con, p.resolve(), raw, prefix=f"{i + 1}_",
                                      tables=[t for t in raw_tables if t in TABLES])
                live.append(parts)
            if union_views:
                con.execute(f"USE {catalog_of(i)}")
                con.execute(VIEWS_SQL)
        con.execute(f"USE {DEFAULT_CATALOG}")
        if union_views:
            _create_union_views(con, run_names(runs))
        lock_configuration(con)
    except BaseException:
        con.close()
        raise
    return con, live


def _create_union_views(con: duckdb.DuckDBPyConnection, names: Sequence[str]) -> None:
    """Every view and raw table as the union of each run's, with the run's name first."""
    con.execute("CREATE SCHEMA raw")
    for schema, views in (("main", VIEW_NAMES), ("raw", (*TABLES, "run"))):
        for view in views:
            union = " UNION ALL BY NAME ".join(
                f'SELECT {_sql_str(name)} AS "{RUN_COLUMN}", * FROM {catalog_of(i)}.{schema}.{view}'
                for i, name in enumerate(names))
            con.execute(f"CREATE VIEW {schema}.{view} AS {union}")


def open_runs(given: Sequence[str | Path]) -> SeveralRunsConnection:
    """A sandboxed connection on several runs (paths, names under runs/, folders of runs), every view
    with a first column `run`."""
    paths, _ = expand_runs(given)
    return SeveralRunsConnection(paths, run_names(paths))


def each_run_stream(con: SeveralRunsConnection, sql: str, params: dict[str, Any] | None = None,
                    limit: int | None = None, offset: int = 0,
                    needs: tuple[str, str] | None = None) -> "tuple[pa.Schema, Iterator[pa.RecordBatch]]":
    """A query written for one run (a saved query) run on each run in turn, its rows prefixed by the
    run's name in a first column `run`; rows [offset, offset+limit) of the whole, streamed: one run's
    rows are read while they are written. `needs` (a saved query's: "games" or
    "board", and why): refuse (ValueError naming the run) a run it cannot read (kind.can_read)."""
    import pyarrow as pa  # deferred: see TYPE_CHECKING above

    from tracelab.store.arrow_build import strings
    if needs is not None:
        for i, name in enumerate(con.names):
            con.use(i)
            try:
                if not can_read(con, needs[0]):
                    raise ValueError(f"{con.runs[i]}: is not a run of games (a reasoning run?), and this query "
                                     f"reads {needs[0]} ({needs[1]})")
            finally:
                con.use(None)
    first = _open_reader(con, 0, sql, params)
    schema = pa.schema([pa.field(RUN_COLUMN, pa.string()), *first.schema])

    def batches() -> "Iterator[pa.RecordBatch]":
        reader: pa.RecordBatchReader | None = first
        for i, name in enumerate(con.names):
            try:
                reader = reader or _open_reader(con, i, sql, params)
                for batch in _refusing(reader):
                    named = strings([name] * batch.num_rows)  # not pa.array: it imports pandas
                    yield pa.RecordBatch.from_arrays([named, *batch.columns], schema=pa.schema(
                        [schema.field(0), *batch.schema])).cast(schema)
            finally:
                if reader is not None:
                    reader.close()   # the connection runs nothing else while a result is open
                reader = None
                con.use(None)

    return schema, _sliced(batches(), limit, offset)


def _open_reader(con: SeveralRunsConnection, index: int, sql: str,
                 params: dict[str, Any] | None) -> "pa.RecordBatchReader":
    """The query's rows on run `index`'s own views; the connection reads that run until con.use(None)."""
    con.use(index)
    try:
        return query_readonly(con, sql, params).to_arrow_reader(BATCH_ROWS)
    except duckdb.PermissionException as e:
        con.use(None)
        raise refusal(e) from None
    except BaseException:
        con.use(None)
        raise
