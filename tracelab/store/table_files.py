"""Writing a query's result (an Arrow table) as CSV or Parquet: the one way, shared by the CLI's
`--format csv|parquet --output` (tracelab/commands/_output.py) and the TUI's export of a SQL result."""
from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, TextIO

from tracelab.engine.safe_files import replacing
from tracelab.errors import UserError

if TYPE_CHECKING:  # imported where used, so that `tracelab --help` stays fast
    import pyarrow as pa


def cell_text(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:g}"
    if isinstance(v, (list, tuple)):
        return "[" + ",".join(cell_text(x) for x in v) + "]"
    return str(v)


def column_values(column: "pa.Array | pa.ChunkedArray", name: str) -> list[Any]:
    """A column's values as Python objects. Dates and times Python cannot hold (DuckDB's 'infinity',
    the year 290000, nanoseconds) come as Arrow's text for them."""
    try:
        return column.to_pylist()
    except (OverflowError, ValueError):
        import pyarrow as pa
        try:
            return column.cast(pa.string()).to_pylist()
        except pa.ArrowException:
            raise UserError(f"column {name!r} holds a date or time outside what Python can show; "
                            "cast it to VARCHAR in the query") from None


def python_rows(table: "pa.Table | pa.RecordBatch") -> list[dict[str, Any]]:
    columns = [column_values(table.column(i), name) for i, name in enumerate(table.schema.names)]
    return [dict(zip(table.schema.names, row)) for row in zip(*columns)] if columns else []


def write_csv(schema: "pa.Schema", batches: "Iterable[pa.RecordBatch]", out: TextIO) -> int:
    """A header line, then one line per row (lists as `[a,b]`, nulls empty), one batch in memory at a
    time; returns the number of rows."""
    import pyarrow as pa
    names, n = schema.names, 0
    w = csv.writer(out)
    w.writerow(names)
    nested = [pa.types.is_nested(t) for t in schema.types]
    for batch in batches:  # column by column: far fewer Python objects than a dict per row
        columns = [[cell_text(v) for v in column_values(col, name)] if is_nested else column_values(col, name)
                   for col, name, is_nested in zip(batch.columns, names, nested)]
        w.writerows(zip(*columns))
        n += batch.num_rows
    return n


def write_parquet(schema: "pa.Schema", batches: "Iterable[pa.RecordBatch]", path: str | IO[bytes]) -> int:
    """Batches into a Parquet file (zstd; a path, or a binary file left open) as they come; returns the
    number of rows."""
    import pyarrow.parquet as pq
    n = 0
    with pq.ParquetWriter(path, schema, compression="zstd") as writer:
        for batch in batches:
            writer.write_batch(batch)
            n += batch.num_rows
    return n


EXPORT_FORMATS = {".csv": "csv", ".parquet": "parquet", ".pq": "parquet"}


def write_table_file(table: "pa.Table", path: str | os.PathLike[str]) -> int:
    """`table` into the file `path`, as CSV or Parquet by its suffix (UserError for another suffix);
    written beside it first and then renamed over it, so a failure leaves no half file and an existing
    file is replaced whole. Returns the number of rows."""
    path = Path(path)
    fmt = EXPORT_FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise UserError(f"{path}: the name must end in .csv or .parquet (it says which format to write)")
    with replacing(path) as f:
        if fmt == "csv":
            text = io.TextIOWrapper(f, newline="", encoding="utf-8")
            n = write_csv(table.schema, table.to_batches(), text)
            text.flush()
            text.detach()  # `replacing` closes the file itself
        else:
            n = write_parquet(table.schema, table.to_batches(), f)
    return n
