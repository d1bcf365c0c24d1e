"""viewers/replay/columns.py: columns built once for several entities and sent to each as its slice give
each entity exactly its own rows (read back from a saved .rrd through rerun's chunk reader)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
from rerun.chunk import RrdReader
from tracelab.viewers.replay.columns import send_per_entity


def test_each_entity_gets_its_own_slice_of_the_rows(tmp_path: Path) -> None:
    path = tmp_path / "split.rrd"
    rec = rr.RecordingStream("tracelab-test", recording_id="split")
    rec.save(path)
    steps = np.array([0, 3, 1, 2, 5, 7])                        # a: 2 rows, b: none, c: 4 rows
    send_per_entity(rec, ["/a", "/b", "/c"], [2, 0, 4], [rr.TimeColumn("step", sequence=steps)],
                    rr.Points2D.columns(positions=np.arange(12, dtype=np.float32).reshape(6, 2),
                                        labels=[f"row {i}" for i in range(6)]))
    rec.flush()
    rec.disconnect()
    rows: dict[str, list[tuple[int, str, list[float]]]] = {}
    reader = RrdReader(path)
    for chunk in reader.stream(store=reader.recordings()[0]):
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if "step" not in names:
            continue
        labels = batch.column(next(n for n in names if n.endswith("labels"))).to_pylist()
        positions = batch.column(next(n for n in names if n.endswith("positions"))).to_pylist()
        rows.setdefault(chunk.entity_path, []).extend(
            (s, lab[0], pos[0]) for s, lab, pos in zip(batch.column("step").to_pylist(), labels, positions))
    assert sorted(rows["/a"]) == [(0, "row 0", [0.0, 1.0]), (3, "row 1", [2.0, 3.0])]
    assert sorted(rows["/c"]) == [(1, "row 2", [4.0, 5.0]), (2, "row 3", [6.0, 7.0]),
                                  (5, "row 4", [8.0, 9.0]), (7, "row 5", [10.0, 11.0])]
    assert not rows.get("/b")
