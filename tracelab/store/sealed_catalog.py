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
refuses anything else with one line naming the entry."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import duckdb

from tracelab.store.schema import ADDED_COLUMNS, ADDED_TABLES, STORED_COLUMNS, VIEW_NAMES

SCHEMA_NAMES = ("main", "raw")
# Catalog entries no sealed run holds: the names a file has of each kind (parameter: its database).
_NEVER_HELD: dict[str, str] = {
    "a macro": "SELECT schema_name, function_name FROM duckdb_functions() WHERE database_name = ?",
    "a sequence": "SELECT schema_name, sequence_name FROM duckdb_sequences() WHERE database_name = ?",
    "an index": "SELECT schema_name, index_name FROM duckdb_indexes() WHERE database_name = ?",
    "a trigger": "SELECT schema_name, trigger_name FROM duckdb_triggers() WHERE database_name = ?",
    "a constraint": "SELECT schema_name, table_name || ' ' || constraint_type FROM duckdb_constraints() "
                  "WHERE database_name = ?",
    # every database lists DuckDB's own types, as internal ones
    "a type": "SELECT schema_name, type_name FROM duckdb_types() WHERE database_name = ? AND NOT internal",
    "a coordinate system": "SELECT schema_name, crs_name FROM duckdb_coordinate_systems() "
                         "WHERE database_name = ?",
}
_RUNS_SQL = "tracelab does not open runs whose data is computed by SQL they bring along"
_NOT_A_RUN = "which a tracelab run does not have"


class SealedFileRefused(ValueError):
    """A sealed run file whose catalog is not the one `seal` writes (one line, names the entry)."""


def check_sealed_catalog(con: duckdb.DuckDBPyConnection, database: str, path: Path) -> dict[str, set[str]]:
    """Refuse (SealedFileRefused) the attached `database` unless it holds what a sealed run holds and
    nothing else; return the columns each raw table has (an older run lacks some ADDED_COLUMNS, and has
    no columns of an ADDED_TABLES table it lacks)."""
    catalog = _Catalog(con, database)
    try:
        catalog.check_entries()
        return catalog.check_columns()
    except SealedFileRefused as e:
        raise SealedFileRefused(f"{str(path)!r}: {e}") from None


def _name(*parts: str) -> str:
    """A name from the file, on one line and cut short (a stranger chose it)."""
    text = ".".join(parts)
    return text if text.isprintable() and len(text) <= 80 else repr(text[:80])


# The entries check_entries looks at, by kind: (schema, name) of each, or (schema, parent) of a schema.
_ENTRIES: dict[str, str] = {
    "schema": "SELECT schema_name, parent_schema FROM duckdb_schemas() WHERE database_name = ?",
    "view": "SELECT schema_name, view_name FROM duckdb_views() WHERE database_name = ?",
    "table": "SELECT schema_name, table_name FROM duckdb_tables() WHERE database_name = ?",
    **_NEVER_HELD,
}


class _Catalog:
    def __init__(self, con: duckdb.DuckDBPyConnection, database: str) -> None:
        self.con = con
        self.database = database
        # every kind of entry in one statement (each statement costs its own planning and run)
        union = " UNION ALL ".join(f"SELECT {i} AS kind, * FROM ({sql})" for i, sql in enumerate(_ENTRIES.values()))
        kinds = list(_ENTRIES)
        self.entries: dict[str, list[tuple[Any, ...]]] = {kind: [] for kind in kinds}
        for kind, *entry in con.execute(f"{union} ORDER BY ALL", [database] * len(kinds)).fetchall():
            self.entries[kinds[kind]].append(tuple(entry))

    def rows(self, sql: str) -> list[tuple[Any, ...]]:
        return self.con.execute(sql, [self.database]).fetchall()

    def check_entries(self) -> None:
        """Schemas, views and tables are the expected ones; nothing of any other kind."""
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
        for table, column, data_type, default, generated in self.rows(
                "SELECT table_name, column_name, data_type, column_default, is_generated FROM duckdb_columns() "
                "WHERE database_name = ? AND schema_name = 'raw' ORDER BY table_name, column_index"):
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
