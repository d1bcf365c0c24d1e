"""Open a run for reading, live or sealed, as a sandboxed in-memory DuckDB connection with the store's
views: the one way anything in tracelab reads a run (commands, saved queries, the TUI).

The connection can read the run's own files and nothing else, writes nothing, never reaches the network
and never loads an extension (tracelab.store.sandbox; docs/store.md, "Security model"). Opening a run
never runs SQL the run supplies: a sealed file's catalog must be what `seal` writes, checked before
anything is read (tracelab.store.sealed_catalog), and a live run's manifest may only name files inside
its parts/ directory.

Live run (a directory of Parquet parts): raw.<table> are views over read_parquet() of the files the run's
manifest lists (tracelab.store.parts), held in DuckDB variables that LiveRunConnection brings up to date
before every statement; so one connection sees every flush as it lands, all tables at the same moment,
and nothing locks the writer out. raw.run is rebuilt when the run's status changes, which is read at
query time from the writer's lock. A query running longer than the writer's grace period (30 s) after a
compaction, or a `seal` that removes the parts, can fail with "file not found" (never return wrong
rows): long-lived readers run queries through retrying(), and a live connection moves to the sealed file
once the run is sealed.
Sealed run (run.duckdb, or any lone .duckdb file): the file is attached READ_ONLY and raw.<table> are
views over its stored tables, made with the user-facing views as statements name them
(SealedRunConnection). Either way the user-facing views (tracelab.store.schema.VIEWS_SQL) are the
same."""
from __future__ import annotations

import os
import re
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, TypeVar

import duckdb

from tracelab.engine.duckdb_limits import exact_file
from tracelab.engine.safe_files import JSON_CAP, check_regular, read_bytes
from tracelab.store import layout
from tracelab.store.checked_files import file_identity, same_file
from tracelab.store.sandbox import (
    LOCK_CONFIGURATION_SQL,
    check_readonly,
    lock_configuration,
    lock_down,
    lock_down_sql,
    refusal,
    sandbox_connection,
)
from tracelab.store.schema import (
    ADDED_COLUMNS,
    ADDED_TABLES,
    RUN_COLUMNS,
    STORED_COLUMNS,
    TABLES,
    VIEW_STATEMENTS,
    VIEWS_SQL,
    empty_sql,
)
from tracelab.store.sealed_catalog import SealedCatalog, SealedFileRefused, check_sealed_catalog

if TYPE_CHECKING:  # loaded by what streams Arrow (arrow_stream): a command printing a table needs none
    import pyarrow as pa

# deferred: pyarrow, for a live run's parts (store.parts) and Arrow streams only: the reading commands that print
# DuckDB's rows open every run through this module

RUNS_DIR = Path("runs")
T = TypeVar("T")


class RunInfo(NamedTuple):  # a NamedTuple, not a dataclass: ~1 ms less start-up
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
    """The run's sealed DuckDB file, if it has one: the lone file the user named, or the run's
    run.duckdb (a regular file of the run, not a link: layout.run_path). Anything else is refused
    before DuckDB opens it: a FIFO would hang it."""
    if not p.is_dir():
        return check_regular(p)
    s = layout.sealed_path(p)
    if not os.path.lexists(s):
        return None
    return check_regular(s, follow_symlinks=False)


def sealed_file_of_run(p: Path) -> Path | None:
    """The run's sealed file (see _sealed_file), None for a live run directory; ValueError for a path
    that is neither."""
    sealed = _sealed_file(p)
    if sealed is None and not p.is_dir():
        raise ValueError(f"{str(p)!r} is neither a run directory nor a sealed .duckdb file")
    return sealed


def run_info(run: str | Path) -> RunInfo:
    """The run's metadata and its status now."""
    p = resolve_run(run)
    sealed = _sealed_file(p)
    if sealed is not None and not p.is_dir():
        con = open_run(p)
        try:
            rel = con.execute("SELECT * FROM raw.run")
            cols = [d[0] for d in rel.description]
            row = rel.fetchone()
        finally:
            con.close()
        if row is None:
            raise ValueError(f"{str(p)!r} has no row in raw.run: not a tracelab run")
        meta = dict(zip(cols, row))
        return RunInfo(p, sealed, meta, str(meta.get("status")))
    from tracelab.store.meta import current_meta  # deferred: a sealed run's readers never read meta.json
    meta = current_meta(p)
    return RunInfo(p, sealed, meta, meta["status"])


def _parts_variable(table: str, prefix: str = "") -> str:
    return f"tracelab_parts_{prefix}{table}"


class LiveParts:
    """What keeps one live run's raw.<table> views current on a connection: the DuckDB variables naming
    the parts its manifest lists, and its raw.run row while its status can still change. `raw` is the
    schema of its raw views ("raw", or "run_2.raw" among several runs) and `prefix` tells its variables
    from another run's on the same connection."""

    def __init__(self, con: duckdb.DuckDBPyConnection, run_dir: Path, raw: str = "raw",
                 prefix: str = "") -> None:
        self.con = con
        self.run_dir = run_dir
        self.raw = raw
        self.prefix = prefix
        self._seen = b""
        self._status: str | None = None

    def sealed_now(self) -> bool:
        return _sealed_file(self.run_dir) is not None

    def update(self, ready: bool) -> bool:
        """Bring the variables up to the manifest's latest flush and raw.run up to the run's status
        (cheap when nothing changed). False, with nothing changed, once the run is sealed: the caller
        reopens it on run.duckdb (only once the views exist, `ready`; before that a sealed run whose
        parts are gone raises)."""
        if ready and self.sealed_now():
            return False
        try:
            raw = read_bytes(layout.manifest_path(self.run_dir), JSON_CAP, what="parts manifest",
                             follow_symlinks=False)
        except FileNotFoundError:
            if not ready or not self.sealed_now():
                raise
            return False   # sealed between the two looks
        if raw != self._seen:
            from tracelab.store.parts import read_manifest
            for table, files in read_manifest(self.run_dir).items():
                self.con.execute(f"SET VARIABLE {_parts_variable(table, self.prefix)} = ?",
                                 [[exact_file(f) for f in files]])
            self._seen = raw
        if self._status in (None, "running"):
            from tracelab.store.meta import current_meta, meta_row
            doc = current_meta(self.run_dir)
            if doc["status"] != self._status:
                _replace_run_table(self.con, meta_row(doc, doc["status"]), self.raw)
                self._status = doc["status"]
        return True


class RefreshingConnection:
    """A DuckDB connection (`_con`) whose views are brought up to date (`refresh`) before every
    statement; everything else is the DuckDB connection's own API."""
    _con: duckdb.DuckDBPyConnection

    def refresh(self) -> None:
        raise NotImplementedError

    def execute(self, query: Any, parameters: Any = None) -> duckdb.DuckDBPyConnection:
        self.refresh()
        return self._con.execute(query, parameters)

    def sql(self, query: str, **options: Any) -> duckdb.DuckDBPyRelation:
        self.refresh()
        return self._con.sql(query, **options)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._con, name)


class LiveRunConnection(RefreshingConnection):
    """A DuckDB connection on a run being written. Before each statement it re-reads the run's manifest
    and, if it changed, points every raw.<table> view at the parts it lists (DuckDB variables read by the
    views), and while the run is running it rebuilds raw.run when its status changed (a writer closing
    or dying); everything else is the DuckDB connection's own API (LiveParts does the updating).

    Once the run is sealed (`tracelab seal`, from any process) it moves over to the sealed file: seal
    writes run.duckdb before it removes the parts, so a statement that finds the sealed file, or finds
    the parts gone, reopens the run on run.duckdb; a statement already reading parts that vanish fails
    with "No such file" and succeeds when run again (retrying())."""

    def __init__(self, con: duckdb.DuckDBPyConnection, run_dir: Path) -> None:
        self._con = con
        self._run_dir = run_dir
        self._parts = LiveParts(con, run_dir)
        self._ready = False   # the views exist (open_run done): only then can it move to the sealed file
        self.sealed = False   # reading run.duckdb now
        self.refresh()

    def refresh(self) -> None:
        """Bring the views up to the run's latest flush and status, or move to the sealed file once
        there is one."""
        if not self.sealed and not self._parts.update(self._ready):
            self._move_to_sealed()

    def views_ready(self) -> None:
        """open_run has built the views: from now on a seal moves the connection to the sealed file."""
        self._ready = True

    def _move_to_sealed(self) -> None:
        sealed = open_run(self._run_dir)
        old, self._con = self._con, sealed
        self.sealed = True
        old.close()

class SealedRunConnection(RefreshingConnection):
    """A sealed run's connection whose views are made when a statement first names them: a view (or a
    raw.<table>) is made, with the views it reads, before the first statement that names it (_names_in),
    and every view before a statement that may list them (SHOW, DESCRIBE, DuckDB's catalog
    functions and schemas) or that names a table there is none of (so DuckDB's error, and its "did you
    mean", is the one the full set of views gives), or before any use of the connection but running a
    statement (cursor() and the like). Making the 35 views costs about as much CPU as a command's
    queries, and a command reads a few."""

    def __init__(self, con: duckdb.DuckDBPyConnection, database: str, columns: dict[str, set[str]]) -> None:
        self._con = con
        self._database = database
        self._columns = columns   # what each stored table has (sealed_catalog.check_sealed_catalog)
        self._made: set[str] = set()   # "raw.<table>" and view names
        self._making = threading.Lock()   # two threads' statements must not make one view twice

    def refresh(self) -> None:
        pass   # a sealed run does not change

    def make_views(self, names: Iterable[str] | None = None) -> None:
        """The views `names` (view names, "raw.<table>"; None: all of them) and those they read."""
        with self._making:
            missing, sql = self.views_sql(names)
            if missing:
                self._con.execute(sql)
                self.views_made(missing)

    def views_sql(self, names: Iterable[str] | None = None) -> tuple[list[str], str]:
        """The views `names` and those they read that are not made yet, and the statements that make them,
        for a caller that runs them with others in one call (_attach_sealed) and then calls views_made."""
        wanted = _ALL_VIEWS if names is None else _with_dependencies(names)
        missing = [n for n in wanted if n not in self._made]
        return missing, ";\n".join(VIEW_STATEMENTS[n] if n in VIEW_STATEMENTS else
                                    _sealed_raw_view_sql(n[4:], self._columns, self._database, "raw")
                                    for n in missing)

    def views_made(self, names: Iterable[str]) -> None:
        self._made.update(names)

    def _run(self, query: Any, run: Callable[[], T]) -> T:
        text = getattr(query, "query", query)   # a DuckDB Statement, or its text
        self.make_views(_named(text) if isinstance(text, str) else None)
        try:
            return run()
        except duckdb.CatalogException:
            if len(self._made) == len(_ALL_VIEWS):
                raise
            self.make_views()   # a name the statement did not show as a word, or no view at all
            return run()

    def execute(self, query: Any, parameters: Any = None) -> duckdb.DuckDBPyConnection:
        return self._run(query, lambda: self._con.execute(query, parameters))

    def sql(self, query: str, **options: Any) -> duckdb.DuckDBPyRelation:
        return self._run(query, lambda: self._con.sql(query, **options))

    def __getattr__(self, name: str) -> Any:
        if name not in _NO_VIEWS_NEEDED:
            self.make_views()
        return getattr(self._con, name)


# What a sealed run's views read: raw.<table> for each stored table, and each view's views and tables.
_ALL_VIEWS: tuple[str, ...] = (*(f"raw.{t}" for t in STORED_COLUMNS), *VIEW_STATEMENTS)
# Words of a statement that may list the views, or read the catalog
_LISTING = re.compile(r"\b(show|describe|information_schema|pg_catalog|sqlite_master|pg_\w+|duckdb_\w+|"
                      r"pragma_\w+|query_table)\b")
# Attributes of the connection that run nothing on the views
_NO_VIEWS_NEEDED = frozenset({"close", "interrupt", "extract_statements", "description", "fetchall", "fetchone",
                              "fetchmany", "rowcount"})


def _named(sql: str) -> list[str] | None:
    """The views and raw tables a statement may read (_names_in); None: it may list them all."""
    return None if _LISTING.search(sql.lower()) else _names_in(sql)


# A raw table named (raw.<table>, "raw"."<table>"); a name not after a dot (`c.steps` is a column) or
# after `main.`: a view's
_RAW_NAME = re.compile(r'\braw"?\s*\.\s*"?(\w+)')
_VIEW_NAME = re.compile(r'(?<![\w.])"?(\w+)|\bmain"?\s*\.\s*"?(\w+)')


def _names_in(sql: str) -> list[str]:
    """Every view whose name is a word of the text, every raw table named as raw.<table> (a column or
    alias of a view's name too: a view too many costs little, one too few is made when DuckDB misses it)."""
    text = sql.lower()
    tables = set(_RAW_NAME.findall(text))
    words = {a or b for a, b in _VIEW_NAME.findall(text)}
    return [n for n in _ALL_VIEWS if (n[4:] in tables if n.startswith("raw.") else n in words)]


def _with_dependencies(names: Iterable[str]) -> list[str]:
    """`names` and the views and raw tables they read, each after what it reads (in _ALL_VIEWS's order)."""
    wanted, todo = set(), list(names)
    while todo:
        name = todo.pop()
        if name in wanted:
            continue
        wanted.add(name)
        if name in VIEW_STATEMENTS:
            todo += [n for n in _names_in(VIEW_STATEMENTS[name].split(" AS", 1)[1]) if n != name]
    return [n for n in _ALL_VIEWS if n in wanted]


RunConnection = duckdb.DuckDBPyConnection | RefreshingConnection


def open_run(run: str | Path) -> RunConnection:
    """A sandboxed DuckDB connection on the run with the views changes, firings, episodes, steps, metrics,
    rules, facts, atoms, groundings, run (and raw.* underneath). Works on a run being written: then every
    statement sees the latest flush."""
    p = resolve_run(run)
    sealed = sealed_file_of_run(p)
    con = sandbox_connection()
    try:
        if sealed is not None:
            result: RunConnection = _attach_sealed(con, sealed)   # its configuration locked too
        else:
            lock_down(con, [check_live_run(p)])
            con.execute("CREATE SCHEMA raw")
            result = LiveRunConnection(con, p.resolve())  # sets the variables the views read, and raw.run
            create_live_raw_views(con, p.resolve())
            con.execute(VIEWS_SQL)
            lock_configuration(con)
            result.views_ready()
    except BaseException as e:
        con.close()
        if isinstance(e, (OSError, duckdb.IOException)) and sealed is None and _sealed_file(p) is not None:
            return open_run(p)  # sealed (its parts removed) while it was being opened: read the sealed file
        raise
    return result


def check_live_run(p: Path) -> str:
    """Refuse a live run directory that is not a run or whose parts/ holds links or special files (before
    anything reads it); returns the one directory a query on it may read (for allowed_directories)."""
    from tracelab.store.meta import current_meta
    current_meta(p)  # a directory without meta.json is not a run: say so first
    _refuse_links(layout.parts_dir(p))
    return str(p.resolve() / layout.PARTS) + "/"


def create_live_raw_views(con: duckdb.DuckDBPyConnection, run_dir: Path, raw: str = "raw",
                          prefix: str = "", tables: Sequence[str] = TABLES) -> None:
    """The views `raw`.<table> over the parts the run's manifest lists (read from the DuckDB variables
    LiveParts keeps current: it must have run once); `tables`: those of the part tables only."""
    from tracelab.store.parts import read_manifest
    listed = read_manifest(run_dir)
    for t in tables:
        if not listed[t]:  # a table added after the run was written (schema.ADDED_TABLES)
            con.execute(f"CREATE VIEW {raw}.{t} AS {empty_sql(t)}")
            continue
        parts = f"read_parquet(getvariable({_sql_str(_parts_variable(t, prefix))}))"
        con.execute(f"CREATE VIEW {raw}.{t} AS SELECT * FROM {parts}")
        have = {c for (c, *_) in con.execute(f"DESCRIBE {raw}.{t}").fetchall()}
        extra = _defaults_for_missing(t, have)
        if extra:  # parts written before a column was added
            con.execute(f"CREATE OR REPLACE VIEW {raw}.{t} AS SELECT *, {extra} FROM {parts}")


def _refuse_links(parts: Path) -> None:
    """A live run's parts/ is readable by queries (DuckDB checks paths, not where links lead, and a FIFO
    would hang the query that names it): refuse a run that keeps anything in it but folders and
    regular files."""
    for entry in parts.rglob("*"):
        if entry.is_symlink():
            raise layout.refused_link(entry)
        if not (entry.is_dir() or entry.is_file()):
            check_regular(entry, follow_symlinks=False)  # FileRefused naming what it is


def check_run_rows(con: duckdb.DuckDBPyConnection, runs: Sequence[tuple[Path, str]], before: str = "") -> None:
    """Each run's raw.run (`runs`: (its file, the schema of its raw views)) is its one metadata row:
    every reader of a run takes it for granted. One statement for them all, run in the same call as the
    statements `before` (each call costs its own round trip)."""
    if not runs:
        if before:
            con.execute(before)
        return
    # fetchall: a result read by fetchone is left unfinished after several statements, and DuckDB refuses the
    # connection's next statement
    ((counts,),) = con.execute((before + ";\n" if before else "") + "SELECT ["
                               + ", ".join(f"(SELECT count(*) FROM {raw}.run)" for _, raw in runs) + "]").fetchall()
    for (sealed, _), rows in zip(runs, counts):
        if rows != 1:
            raise ValueError(f"{sealed}: raw.run holds {rows} rows, not the run's one metadata row: not a "
                             "tracelab run, or a damaged one")


def _attach_sealed(con: duckdb.DuckDBPyConnection, sealed: Path) -> SealedRunConnection:
    """Attach the sealed file read-only (before external access is switched off: ATTACH needs the file),
    check its catalog before reading anything (tracelab.store.sealed_catalog), check raw.run and lock the
    connection's configuration; raw.<table> over its stored tables and the views are made as statements
    name them (SealedRunConnection). Three calls of DuckDB when the file was checked before: each costs
    its own round trip (~1 ms of a cold `why --action`)."""
    identity = attach_sealed_file(con, sealed, "store", then=f"{lock_down_sql()};\nCREATE SCHEMA raw")
    result = SealedRunConnection(con, "store", check_sealed_catalog(con, "store", sealed, identity=identity))
    made, views = result.views_sql(["raw.run"])
    check_run_rows(con, [(sealed, "raw")], before=f"{views};\n{LOCK_CONFIGURATION_SQL}")
    result.views_made(made)
    return result


def attach_sealed_file(con: duckdb.DuckDBPyConnection, sealed: Path, database: str,
                       then: str = "") -> os.stat_result | None:
    """ATTACH the sealed file READ_ONLY as `database`, then run the statements `then` in the same call;
    refused if a write-ahead log lies beside it. Returns the identity of the file attached (checked_files:
    the same before and after), or None."""
    path = sealed.resolve()
    wal = Path(f"{path}.wal")
    if os.path.lexists(wal):  # ATTACH replays a write-ahead log, running the SQL in it (ALTER ... USING)
        raise SealedFileRefused(f"{str(wal)!r}: a sealed run has no write-ahead log, and tracelab does not "
                                "replay one it brings along (it holds SQL that would run on opening)")
    before = file_identity(path)
    con.execute(f"ATTACH {_sql_str(path)} AS {database} (READ_ONLY)" + (f";\n{then}" if then else ""))
    after = file_identity(path)
    return after if same_file(before, after) else None


def sealed_raw_views_sql(con: duckdb.DuckDBPyConnection, sealed: Path, database: str, raw: str,
                         catalog: SealedCatalog | None = None,
                         tables: Sequence[str] = tuple(STORED_COLUMNS),
                         identity: os.stat_result | None = None) -> str:
    """Check the attached file's whole catalog (nothing of it is read before; `catalog`: its entries read
    with other files', sealed_catalog.read_sealed_catalogs; `identity`: attach_sealed_file's), then the
    statements that make the views `raw`.<table> over its stored tables (with the added columns and
    tables an older run lacks; `tables`: those only; raw.run always). The caller runs them, several
    runs' in one go, then checks raw.run (check_run_rows)."""
    columns = check_sealed_catalog(con, database, sealed, catalog, identity)
    return ";\n".join(_sealed_raw_view_sql(t, columns, database, raw) for t in dict.fromkeys([*tables, "run"]))


def _sealed_raw_view_sql(table: str, columns: dict[str, set[str]], database: str, raw: str) -> str:
    """The view `raw`.<table> over the attached file's stored table, whose columns are `columns[table]`."""
    if table in ADDED_TABLES and not columns[table]:  # a table added after the run was sealed
        return f"CREATE VIEW {raw}.{table} AS {empty_sql(table)}"
    extra = _defaults_for_missing(table, columns[table])
    cols = ", ".join([f'"{c}"' for c in STORED_COLUMNS[table] if c in columns[table]] + ([extra] if extra else []))
    return f"CREATE VIEW {raw}.{table} AS SELECT {cols} FROM {database}.raw.{table}"


def _defaults_for_missing(table: str, have: set[str]) -> str:
    """`value AS "column"` for the added columns (schema.ADDED_COLUMNS) a run written earlier lacks."""
    return ", ".join(f'{value} AS "{c}"' for c, value in ADDED_COLUMNS.get(table, {}).items() if c not in have)


def _create_table(con: duckdb.DuckDBPyConnection, name: str, table: Any) -> None:
    con.register("_tracelab_tmp", table)
    try:
        con.execute(f"CREATE TABLE {name} AS SELECT * FROM _tracelab_tmp")
    finally:
        con.unregister("_tracelab_tmp")


def _replace_run_table(con: duckdb.DuckDBPyConnection, row: dict[str, Any], raw: str = "raw") -> None:
    """(Re)create raw.run from meta_row()'s one row. By parameters, not register(): DuckDB refuses
    register() while the caller still holds an unfinished result of this connection."""
    select = ", ".join(f'CAST(? AS {RUN_COLUMNS[c]}) AS "{c}"' for c in row)
    con.execute(f"CREATE OR REPLACE TABLE {raw}.run AS SELECT {select}", list(row.values()))


def query_readonly(con: RunConnection, sql: str,
                   params: dict[str, Any] | None = None) -> duckdb.DuckDBPyRelation:
    """One read-only statement (SELECT, including DESCRIBE/SHOW/SUMMARIZE, or EXPLAIN of one) as a lazy
    relation. Raises duckdb errors as they come (their text shows the position in the query) and
    sandbox.QueryRefused (a ValueError) for a statement that is not a query or that reaches outside
    the run."""
    check_readonly(con, sql)
    try:
        return con.sql(sql, params=params or None)
    except duckdb.PermissionException as e:
        raise refusal(e) from None
    except duckdb.InterruptException:  # cancelled (EXPLAIN ANALYZE runs here): never run it again
        raise
    except duckdb.Error:
        # the relation API drops the "LINE 1: ... ^" pointer; binding again through execute() (it fails
        # at the same place, before running anything) raises the error with it
        con.execute(sql, params or None)
        raise


BATCH_ROWS = 65_536


def arrow_stream(rel: duckdb.DuckDBPyRelation, limit: int | None = None,
                 offset: int = 0) -> "tuple[pa.Schema, Iterator[pa.RecordBatch]]":
    """The schema and the rows [offset, offset+limit) of a relation as Arrow record batches, read as
    they are needed: nothing past the limit is computed beyond DuckDB's current batch. A query reaching
    outside the run (refused only as its rows are read) raises sandbox.QueryRefused."""
    try:
        reader = rel.to_arrow_reader(BATCH_ROWS)
    except duckdb.PermissionException as e:
        raise refusal(e) from None
    return reader.schema, _sliced(reader, limit, offset)


def _refusing(batches: "Iterator[pa.RecordBatch]") -> "Iterator[pa.RecordBatch]":
    try:
        yield from batches
    except duckdb.PermissionException as e:
        raise refusal(e) from None


def _sliced(batches: "Iterator[pa.RecordBatch]", limit: int | None, offset: int) -> "Iterator[pa.RecordBatch]":
    skip, left = offset, limit
    for batch in _refusing(batches):
        if skip:
            cut = min(skip, batch.num_rows)
            batch, skip = batch.slice(cut), skip - cut
        if left is not None:
            batch = batch.slice(0, left)
            left -= batch.num_rows
        if batch.num_rows:
            yield batch
        if left == 0:
            return


# DuckDB's number types (a text table aligns them right)
_NUMBER_TYPES = frozenset({"TINYINT", "SMALLINT", "INTEGER", "BIGINT", "HUGEINT", "UTINYINT", "USMALLINT",
                           "UINTEGER", "UBIGINT", "UHUGEINT", "FLOAT", "DOUBLE"})


class QueryRows(NamedTuple):
    """A query's result as Python rows: what a text table prints, read without pyarrow."""
    names: list[str]
    types: list[str]   # DuckDB's type names
    rows: list[tuple[Any, ...]]

    @property
    def numeric(self) -> list[bool]:
        return [t in _NUMBER_TYPES for t in self.types]


def fetch_rows(rel: duckdb.DuckDBPyRelation, limit: int | None = None, offset: int = 0) -> QueryRows:
    """The rows [offset, offset+limit) of a relation as Python tuples; rows past the limit are never
    computed. A query reaching outside the run raises sandbox.QueryRefused."""
    if limit is not None or offset:
        rel = rel.limit(2**62 if limit is None else limit, offset)
    try:
        return QueryRows(list(rel.columns), [str(t) for t in rel.types], rel.fetchall())
    except duckdb.PermissionException as e:
        raise refusal(e) from None


def fetch_arrow(rel: duckdb.DuckDBPyRelation, limit: int | None = None, offset: int = 0) -> "pa.Table":
    """The rows [offset, offset+limit) of a relation as an Arrow table; rows past the limit are never
    materialised."""
    import pyarrow as pa
    schema, batches = arrow_stream(rel, limit, offset)
    return pa.Table.from_batches(list(batches), schema=schema)



# How DuckDB says a part a statement was bound to is gone: when it opens the file, or when it expands the
# file list at the start of the statement.
_PART_GONE = ("No such file", "No files found that match the pattern")


def retrying(fn: Callable[[], T], attempts: int = 4) -> T:
    """fn(), run again (up to `attempts` times) if it failed because a part a query was still to open
    went away: removed by a live run's compaction, or by `seal` (the next attempt reads the sealed
    file, LiveRunConnection.refresh)."""
    for i in range(attempts):
        try:
            return fn()
        except duckdb.IOException as e:
            if not any(m in str(e) for m in _PART_GONE) or i == attempts - 1:
                raise
            time.sleep(0.01 * (i + 1))
    raise AssertionError("unreachable")
