"""The query sandbox: a DuckDB connection that can read one run's own files and nothing else, and the
statement check that gives friendly errors for statements that are not queries.

Two layers (docs/store.md, "Security model"):
1. DuckDB's own controls, set on every connection that reads a run (`sandbox_connection`, `lock_down`):
   - external access off (`enable_external_access = false`): no file outside `allowed_directories`
     (a live run's parts/ directory; a sealed run's file is attached before access is switched off),
     no URL, no COPY/ATTACH/EXPORT to anywhere else;
   - extensions are never installed nor loaded (autoinstall/autoload off, community extensions off);
   - DuckDB's home, extension and secret directories point at a path under /dev/null, where nothing can
     be created: a query writes no file anywhere but DuckDB's own spill files;
   - memory is bounded (`query_memory`: a quarter of the machine's, at most 4 GiB, or
     $TRACELAB_QUERY_MEMORY), and so are the threads and the spill files, which DuckDB writes only in a
     private folder of this process (0700, emptied when the connection closes);
   - `lock_configuration = true` once the views exist, so no statement can switch any of this back.
   The order matters: DuckDB refuses to change `allowed_directories` once external access is off, and
   an ATTACH needs access to the file (and its .wal name), so the sealed file is attached first.
2. `check_readonly`: exactly one statement, a SELECT (DESCRIBE, SHOW, SUMMARIZE, PIVOT, FROM ... are
   SELECTs) or an EXPLAIN [ANALYZE] of one; the statement inside EXPLAIN is checked too, since EXPLAIN
   ANALYZE runs it. This layer names the problem in plain words; layer 1 holds even if it missed one."""
from __future__ import annotations

import atexit
import itertools
import math
import os
import shutil
import tempfile
import weakref
from collections.abc import Sequence

import duckdb

from tracelab.engine.duckdb_limits import (
    GIB,
    QUERY_MEMORY_ENV,
    SandboxSettingError,
    exact_file,
    query_memory,
)
from tracelab.engine.safe_files import human_bytes

# Not a directory, so nothing can ever be created under it (not even by root).
NOWHERE = "/dev/null/tracelab"

SANDBOX_CONFIG: dict[str, object] = {
    "autoinstall_known_extensions": False,
    "autoload_known_extensions": False,
    "allow_community_extensions": False,
    "home_directory": NOWHERE,       # DuckDB would create ~/.duckdb for extensions and secrets
    "extension_directory": NOWHERE,
    "secret_directory": NOWHERE,
}

def out_of_memory_message(e: duckdb.OutOfMemoryException) -> str:
    """DuckDB's out-of-memory error (a dozen lines advising SET statements the sandbox refuses) as one
    line naming the limits and the way to raise them."""
    first = str(e).splitlines()[0].removeprefix("Out of Memory Error: ").rstrip(".")
    try:
        limits = query_memory()
    except SandboxSettingError as bad:
        return f"out of memory ({first}); {bad}"
    bigger = math.ceil(2 * limits.memory / GIB)
    return (f"out of memory ({first}): a query on a run may use {human_bytes(limits.memory)} of memory "
            f"({limits.source}) and spill {human_bytes(limits.spill)} to disk; set {QUERY_MEMORY_ENV} "
            f"to raise both (e.g. {QUERY_MEMORY_ENV}={bigger}G)")


_spill_root: list[str] = []   # this process's private folder for DuckDB's spill files, once made
_spill_names = itertools.count()


def _spill_directory() -> str:
    """A new folder name (DuckDB creates it when it first spills and removes it on close) inside a private
    folder of this process (mkdtemp: 0700, so no other user can plant or read anything there), which is
    removed at exit; "" (no spilling: a query needing more memory fails) where no temp folder can be made."""
    if not _spill_root:
        try:
            root = tempfile.mkdtemp(prefix="tracelab-spill-")
        except OSError:
            return ""
        owner = os.getpid()  # a forked child inherits the handler, not the folder
        atexit.register(lambda: os.getpid() == owner and shutil.rmtree(root, ignore_errors=True))
        _spill_root.append(root)
    return os.path.join(_spill_root[0], f"{os.getpid()}-{next(_spill_names)}")


READONLY_STATEMENTS = {duckdb.StatementType.SELECT}


class QueryRefused(ValueError):
    """A statement the sandbox does not run (one line, names the statement kind or what it touched)."""


# Every connection sandbox_connection made that is still open somewhere: what interrupt_queries stops.
_CONNECTIONS: weakref.WeakSet[duckdb.DuckDBPyConnection] = weakref.WeakSet()


def sandbox_connection(database: str = ":memory:") -> duckdb.DuckDBPyConnection:
    """A DuckDB connection (in memory; `seal` passes the file it builds) with extensions and home
    directories already shut off and its memory, threads and spill files bounded (query_memory), all in
    force before any statement runs; call lock_down() once anything it must attach is attached."""
    config = {**SANDBOX_CONFIG, **query_memory().duckdb_config(), "temp_directory": _spill_directory()}
    con = duckdb.connect(database, config=config)
    _CONNECTIONS.add(con)
    return con


def interrupt_queries() -> None:
    """Stop the query each sandbox connection is running (within DuckDB's next check: milliseconds); a
    connection running none is not affected. Safe from any thread: Ctrl-C's watcher calls it."""
    for con in list(_CONNECTIONS):
        try:
            con.interrupt()
        except duckdb.ConnectionException:
            pass  # closed, and not yet collected: it runs nothing


def _sql_list(items: Sequence[str]) -> str:
    return "[" + ", ".join("'" + s.replace("'", "''") + "'" for s in items) + "]"


def lock_down(con: duckdb.DuckDBPyConnection, allowed_directories: Sequence[str] = ()) -> None:
    """Switch external access off, except for reading under `allowed_directories` (lock_down_sql)."""
    con.execute(lock_down_sql(allowed_directories))


def lock_down_sql(allowed_directories: Sequence[str] = ()) -> str:
    """The statements that switch external access off, except for reading under `allowed_directories`
    (absolute paths ending in '/'), for a caller that runs them with others in one call (each call costs its
    own round trip). Each is allowed as written and as exact_file writes it: a run's files are named to DuckDB
    that way (a folder `r*` as `r[*]`), and DuckDB checks the name it is given as well as the files it
    finds, so a name can still reach only files under a directory as written."""
    statements = []
    if allowed_directories:
        allowed = list(dict.fromkeys([*allowed_directories, *map(exact_file, allowed_directories)]))
        statements.append(f"SET allowed_directories = {_sql_list(allowed)}")
    return ";\n".join([*statements, "SET enable_external_access = false"])


# From here on no SET, RESET or PRAGMA can change any setting of the connection.
LOCK_CONFIGURATION_SQL = "SET lock_configuration = true"


def lock_configuration(con: duckdb.DuckDBPyConnection) -> None:
    """From here on no SET, RESET or PRAGMA can change any setting of this connection."""
    con.execute(LOCK_CONFIGURATION_SQL)


def _explained_statement(query: str) -> str:
    """The statement an EXPLAIN statement explains: what follows EXPLAIN, ANALYZE and an option list."""
    tokens = [(pos, kind) for pos, kind in duckdb.tokenize(query) if kind != duckdb.token_type.comment]

    def word(i: int) -> str:
        pos = tokens[i][0]
        end = tokens[i + 1][0] if i + 1 < len(tokens) else len(query)
        return query[pos:end].strip().upper()

    i = 1  # tokens[0] is EXPLAIN
    if i < len(tokens) and word(i) in ("ANALYZE", "ANALYSE"):
        i += 1
    if i < len(tokens) and word(i).startswith("("):
        depth = 0
        while i < len(tokens):
            w = word(i)
            depth += w.count("(") - w.count(")")
            i += 1
            if depth <= 0:
                break
    return query[tokens[i][0]:] if i < len(tokens) else ""


def check_readonly(con: duckdb.DuckDBPyConnection, sql: str) -> None:
    """Raise QueryRefused unless `sql` is one read-only query (see the module's doc)."""
    statements = con.extract_statements(sql)
    if len(statements) != 1:
        raise QueryRefused(f"expected one SQL statement, got {len(statements)}")
    statement = statements[0]
    if statement.type == duckdb.StatementType.EXPLAIN:
        inner = _explained_statement(statement.query)
        try:
            check_readonly(con, inner)
        except QueryRefused as e:
            raise QueryRefused(f"EXPLAIN runs or plans the statement it explains: {e}") from None
        return
    if statement.type == duckdb.StatementType.MULTI:  # DuckDB's PIVOT first creates a type
        raise QueryRefused("this statement runs several statements (a PIVOT without an IN list creates a "
                           "type first); name the values: PIVOT ... ON col IN ('a', 'b') USING ...")
    if statement.type not in READONLY_STATEMENTS:
        raise QueryRefused(f"only read-only queries are allowed (SELECT, EXPLAIN SELECT); this is a "
                           f"{statement.type.name} statement")


def refusal(e: duckdb.PermissionException) -> QueryRefused:
    """DuckDB's permission error (several lines, with the query) as one line that says why."""
    first = str(e).splitlines()[0].removeprefix("Permission Error: ")
    return QueryRefused(f"a query may read only this run's own files, with no network and no extensions "
                        f"({first})")
