"""A table's small parts are merged once they hold part_rows rows (not only at compact_files files), read
one part at a time, into row groups of MERGE_ROW_GROUP_ROWS: a merge holds about part_rows rows however long
the run, and keeps every row in order."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from tracelab.store import parts
from tracelab.store.parts import TableParts
from tracelab.store.schema import SCHEMAS


def steps_rows(start: int, n: int):  # noqa: ANN201 - a pyarrow Table
    from tracelab.store.convert import steps_table
    return steps_table(np.full(n, 1, np.int64), {"step": np.arange(start, start + n), "action": np.zeros(n),
                                                 "reward": np.zeros(n)})


def test_small_parts_merge_at_part_rows_rows(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(parts, "MERGE_ROW_GROUP_ROWS", 256)
    (tmp_path / "parts").mkdir()
    table = TableParts(tmp_path, "steps", part_rows=1000, compact_files=64)
    for k in range(3):
        table.publish([steps_rows(300 * k, 300)])
    assert table.compactions == 0 and len(table.files) == 4  # the empty first part and three of 300
    table.publish([steps_rows(900, 100), steps_rows(1000, 200)])  # 1,200 rows in small parts: merged
    assert table.compactions == 1 and len(table.files) == 1
    merged = pq.ParquetFile(tmp_path / "parts" / table.files[0])
    assert [merged.metadata.row_group(i).num_rows for i in range(merged.num_row_groups)] == [256] * 4 + [176]
    assert merged.read().column("step").to_pylist() == list(range(1200))
    assert merged.schema_arrow.equals(SCHEMAS["steps"])
    table.publish([steps_rows(1200, 50)])  # a big part is never merged again
    assert table.compactions == 1 and len(table.files) == 2


def test_parts_of_merge_below_rows_are_left_as_written(tmp_path: Path) -> None:
    # a fast traced play publishes parts of 50k-150k rows: merging them re-encoded every row (half the
    # writer's CPU), so a part of MERGE_BELOW_ROWS rows or more is never merged, whatever part_rows is
    (tmp_path / "parts").mkdir()
    table = TableParts(tmp_path, "steps", part_rows=100_000, compact_files=64)
    for k in range(4):  # 4 x 40,000 rows: past part_rows in all
        table.publish([steps_rows(40_000 * k, 40_000)])
    assert table.compactions == 0 and len(table.files) == 5
    table.publish([steps_rows(160_000, 10)])  # a small part is still a small part
    assert table.compactions == 0 and len(table.files) == 6


def test_change_rows_number_their_seq_by_deltas_and_keep_statistics_on_the_filter_columns(tmp_path: Path) -> None:
    from tracelab.store.convert import trace_table
    from tracelab.store.schema import TRACE_COLUMNS
    (tmp_path / "parts").mkdir()
    table = TableParts(tmp_path, "changes", part_rows=1000)
    n = 500
    rows = {name: np.zeros(n, dtype) for name, dtype in TRACE_COLUMNS.items()}
    rows["atom"], rows["grounding"] = np.arange(n) % 7, np.full(n, -1)
    table.publish([trace_table(rows, 3, 0, 7, 0)])
    meta = pq.ParquetFile(tmp_path / "parts" / table.files[-1]).metadata.row_group(0)
    columns = {meta.column(i).path_in_schema: meta.column(i) for i in range(meta.num_columns)}
    assert "DELTA_BINARY_PACKED" in columns["seq"].encodings
    assert columns["seq"].statistics.max == n - 1 and columns["episode"].statistics.min == 3
    assert columns["atom"].statistics is None
    assert pq.read_table(tmp_path / "parts" / table.files[-1]).column("seq").to_pylist() == list(range(n))
