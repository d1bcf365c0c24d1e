"""The store's one schema (tracelab.store.schema.STORED_COLUMNS, DuckDB types) is what the writers store:
the Arrow schemas built from it are stored by DuckDB as exactly those types. The sealed catalog check
compares a file with STORED_COLUMNS without loading pyarrow, so a wrong entry in the Arrow mapping would
refuse every run `seal` writes, or let a column of another type through."""
from __future__ import annotations

import duckdb

from tracelab.store.arrow_build import empty_table
from tracelab.store.meta import meta_table
from tracelab.store.schema import SCHEMAS, STORED_COLUMNS, arrow_schema


def test_the_arrow_schemas_are_stored_as_the_declared_duckdb_types() -> None:
    con = duckdb.connect()
    stored = {t: dict(zip(arrow_schema(t).names, map(str, con.from_arrow(empty_table(arrow_schema(t))).types)))
              for t in STORED_COLUMNS}
    assert stored == STORED_COLUMNS
    assert meta_table({}, "finished").schema == arrow_schema("run")
    assert set(SCHEMAS) == set(STORED_COLUMNS) - {"run"}
