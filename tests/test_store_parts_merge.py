"""A table's small parts are merged once they hold part_rows rows (not only at compact_files files), read
one part at a time, into row groups of ROW_GROUP_ROWS: a merge holds about part_rows rows however long
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
    monkeypatch.setattr(parts, "ROW_GROUP_ROWS", 256)
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
