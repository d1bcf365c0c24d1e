"""What a sealed run file may hold, checked on its catalog before any of its tables is read.

A DuckDB file keeps SQL in several places that run when a table is read or a name is used: a generated
column's expression runs on every read of its table (`repeat('A', 2e9)` took 4 GB), a view's query
whenever it is named, a macro when it is called; defaults, CHECK constraints, index expressions,
triggers and sequences hold expressions too. A file `seal` writes holds none of these: the schemas
`main` and `raw`, the stored tables raw.<table> with the columns and types of tracelab.store.schema
(columns of schema.ADDED_COLUMNS and tables of schema.ADDED_TABLES may be missing: runs sealed before they
existed), and tracelab's views
in `main` (which the reader never uses: it builds its own). `check_sealed_catalog` reads the catalog
through DuckDB's metadata functions, which report stored definitions as text and evaluate nothing, and
refuses anything else with one line naming the entry. A file whose entries and columns passed is recorded
by its identity (tracelab.store.checked_files) with the names of its stored columns (what its views are
made of), and neither is read again while it stays the same (a record's names are taken only where they
are the schema's own: a record holding anything else is not used)."""
from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Collection, Sequence
from functools import cache
from pathlib import Path
from typing import Any

import duckdb

from tracelab.store import checked_files
from tracelab.store.schema import ADDED_COLUMNS, ADDED_TABLES, STORED_COLUMNS, VIEW_NAMES

SCHEMA_NAMES = ("main", "raw")
# Catalog entries no sealed run holds: the database and names of each kind.
_NEVER_HELD: dict[str, str] = {
    "a macro": "SELECT database_name, schema_name, function_name FROM duckdb_functions()",
    "a sequence": "SELECT database_name, schema_name, sequence_name FROM duckdb_sequences()",
    "an index": "SELECT database_name, schema_name, index_name FROM duckdb_indexes()",
    "a trigger": "SELECT database_name, schema_name, trigger_name FROM duckdb_triggers()",
    "a constraint": "SELECT database_name, schema_name, table_name || ' ' || constraint_type FROM duckdb_constraints()",
    # every database lists DuckDB's own types, as internal ones
    "a type": "SELECT database_name, schema_name, type_name FROM duckdb_types() WHERE NOT internal",
    "a coordinate system": "SELECT database_name, schema_name, crs_name FROM duckdb_coordinate_systems()",
}
_RUNS_SQL = "tracelab does not open runs whose data is computed by SQL they bring along"
_NOT_A_RUN = "which a tracelab run does not have"


class SealedFileRefused(ValueError):
    """A sealed run file whose catalog is not the one `seal` writes (one line, names the entry)."""


@cache
def checker_version() -> str:
    """What decides this check's verdict besides the file: this module's text, the schema it checks
    against, DuckDB's version (checked_files records verdicts under it)."""
    h = hashlib.sha256(Path(__file__).read_bytes())
    h.update(repr((STORED_COLUMNS, ADDED_COLUMNS, ADDED_TABLES, VIEW_NAMES, duckdb.__version__)).encode())
    return h.hexdigest()


def entries_checked(identity: os.stat_result | None) -> bool:
    """Whether the file of this identity (checked_files.file_identity, of the file attached) passed
    check_entries before: its entries need not be read again."""
    return checked_files.was_checked(identity, checker_version())


def check_sealed_catalog(con: duckdb.DuckDBPyConnection, database: str, path: Path,
                         catalog: SealedCatalog | None = None,
                         identity: os.stat_result | None = None) -> dict[str, set[str]]:
    """Refuse (SealedFileRefused) the attached `database` unless it holds what a sealed run holds and
    nothing else; return the columns each raw table has (an older run lacks some ADDED_COLUMNS, and has
    no columns of an ADDED_TABLES table it lacks). `catalog`: its entries as read_sealed_catalogs read
    them (with the others' on the connection), else read here. `identity`: the attached file's
    (checked_files): its entries are not read again once they passed, and are recorded when they pass."""
    if catalog is None:
        note = checked_files.checked_note(identity, checker_version())
        recorded = _recorded_columns(note)
        if recorded is not None:
            return recorded
        catalog = read_sealed_catalogs(con, [database], [database] if note is not None else [])[database]
    try:
        if catalog.entries is not None:
            catalog.check_entries()
        columns = catalog.check_columns()
    except SealedFileRefused as e:
        raise SealedFileRefused(f"{str(path)!r}: {e}") from None
    if catalog.entries is not None:
        checked_files.record_checked(identity, checker_version(),
                                     json.dumps({t: sorted(c) for t, c in columns.items()}))
    return columns


def _recorded_columns(note: str | None) -> dict[str, set[str]] | None:
    """The columns a record holds (check_sealed_catalog wrote them), if every name is one of the schema's
    own; else None (no record, an older one without them, or one not written by this check)."""
    try:
        doc = json.loads(note) if note else None
    except ValueError:
        return None
    if not isinstance(doc, dict) or set(doc) != set(STORED_COLUMNS):
        return None
    if not all(isinstance(cols, list) and all(isinstance(c, str) and c in STORED_COLUMNS[t] for c in cols)
               for t, cols in doc.items()):
        return None
    return {t: set(cols) for t, cols in doc.items()}


def _name(*parts: str) -> str:
    """A name from the file, on one line and cut short (a stranger chose it)."""
    text = ".".join(parts)
    return text if text.isprintable() and len(text) <= 80 else repr(text[:80])


# The entries check_entries looks at, by kind: (database, schema, name) of each, or (database, schema,
# parent) of a schema.
_ENTRIES: dict[str, str] = {
    "schema": "SELECT database_name, schema_name, parent_schema FROM duckdb_schemas()",
    "view": "SELECT database_name, schema_name, view_name FROM duckdb_views()",
    "table": "SELECT database_name, schema_name, table_name FROM duckdb_tables()",
    **_NEVER_HELD,
}
_COLUMNS_SQL = ("SELECT database_name, table_name, column_name, data_type, column_default, is_generated "
                "FROM duckdb_columns() WHERE list_contains(?, database_name) AND schema_name = 'raw' "
                "ORDER BY database_name, table_name, column_index")


def read_sealed_catalogs(con: duckdb.DuckDBPyConnection, databases: Sequence[str],
                         entries_known: Collection[str] = ()) -> dict[str, SealedCatalog]:
    """The catalog entries of the attached `databases` (but those of `entries_known`: files whose entries
    passed before, entries_checked), read in two statements for them all: DuckDB's metadata functions
    list every database's entries (its function list, the costly one, with thousands of built-ins), so
    one pass serves every file on the connection."""
    kinds = list(_ENTRIES)
    catalogs = {d: SealedCatalog(d, d not in entries_known) for d in databases}
    unknown = [d for d in databases if d not in entries_known]
    # every kind of entry in one statement (each statement costs its own planning and run)
    union = " UNION ALL ".join(f"SELECT {i} AS kind, * FROM ({sql})" for i, sql in enumerate(_ENTRIES.values()))
    for kind, database, *entry in con.execute(
            f"SELECT * FROM ({union}) WHERE list_contains(?, database_name) ORDER BY ALL",
            [unknown]).fetchall() if unknown else ():
        catalogs[database].entries[kinds[kind]].append(tuple(entry))
    for database, *column in con.execute(_COLUMNS_SQL, [list(databases)]).fetchall():
        catalogs[database].columns.append(tuple(column))
    return catalogs


class SealedCatalog:
    """One attached file's catalog entries, as read_sealed_catalogs read them, and the checks on them."""

    def __init__(self, database: str, read_entries: bool = True) -> None:
        self.database = database
        # None: not read (they passed check_entries before: checked_files)
        self.entries: dict[str, list[tuple[Any, ...]]] | None = {kind: [] for kind in _ENTRIES} if read_entries \
            else None
        self.columns: list[tuple[Any, ...]] = []   # raw's (table, column, type, default, generated), in order

    def check_entries(self) -> None:
        """Schemas, views and tables are the expected ones; nothing of any other kind."""
        assert self.entries is not None
        for schema, parent in self.entries["schema"]:
            if parent is not None or schema not in SCHEMA_NAMES:  # raw nested in another schema too
                raise SealedFileRefused(f"holds a schema {_name(*filter(None, (parent, schema)))}, {_NOT_A_RUN}")
        for schema, view in self.entries["view"]:
            if schema == "raw":
                raise SealedFileRefused(f"holds {_name('raw', view)} as a view, not a stored table: {_RUNS_SQL}")
            if view not in VIEW_NAMES:
                raise SealedFileRefused(f"holds a view {_name(schema, view)}, {_NOT_A_RUN}")
        expected = STORED_COLUMNS
        tables = self.entries["table"]
        for schema, table in tables:
            if schema != "raw" or table not in expected:
                raise SealedFileRefused(f"holds a table {_name(schema, table)}, {_NOT_A_RUN}")
        missing = [t for t in expected if ("raw", t) not in tables and t not in ADDED_TABLES]
        if missing:
            raise SealedFileRefused(f"has no table raw.{missing[0]}: not a tracelab run")
        for kind in _NEVER_HELD:
            found = self.entries[kind]
            if found:
                raise SealedFileRefused(f"holds {kind} {_name(*found[0])}, {_NOT_A_RUN}: {_RUNS_SQL}")

    def check_columns(self) -> dict[str, set[str]]:
        """Each raw table's columns: stored (not generated, no default), expected, of the expected type."""
        expected = STORED_COLUMNS
        have: dict[str, set[str]] = {t: set() for t in expected}
        for table, column, data_type, default, generated in self.columns:
            where = _name("raw", table, column)
            if generated:
                raise SealedFileRefused(f"{where} is a generated column: {_RUNS_SQL}")
            if default is not None:
                raise SealedFileRefused(f"{where} has a default value, {_NOT_A_RUN}: {_RUNS_SQL}")
            want = expected[table].get(column)
            if want is None:
                raise SealedFileRefused(f"raw.{table} has a column {_name(column)}, {_NOT_A_RUN}")
            if data_type != want:
                raise SealedFileRefused(f"{where} is {_name(data_type)}, not {want}: not a tracelab run, or "
                                        "one from an incompatible version")
            have[table].add(column)
        for table, columns in expected.items():
            if table in ADDED_TABLES and not have[table]:  # sealed before the table existed: no columns
                continue
            lacking = [c for c in columns if c not in have[table] and c not in ADDED_COLUMNS.get(table, {})]
            if lacking:
                raise SealedFileRefused(f"raw.{table} has no column {lacking[0]!r}: not a tracelab run, or one "
                                        "from an incompatible version")
        return have
