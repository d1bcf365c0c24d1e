"""Ctrl-C stops every reading command that can run a long query on a big run (trace, why, why-not, diff,
show, runs, sql): the store's queries are interrupted (tracelab.commands._interrupt), exit 130, one line
on stderr, within a few CPU seconds."""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from store_helpers import ctrl_c_after_start, write_walk_run

# Listed parts of the changes table: every one is opened and read by a query, so a query over them takes
# seconds (about 1 ms a part here) in little memory (a few hundred MB). Hard links of one small part:
# no disk.
PARTS = 20_000


@pytest.fixture(scope="module")
def slow_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The walk run whose manifest lists PARTS more parts of the changes table (copies of its first)."""
    run = write_walk_run(tmp_path_factory.mktemp("slow") / "walk")
    manifest = run / "parts" / "manifest.json"
    doc = json.loads(manifest.read_text())
    first = run / "parts" / doc["tables"]["changes"][0]
    for i in range(PARTS):
        name = f"changes/{10_000 + i:08d}.parquet"
        os.link(first, run / "parts" / name)
        doc["tables"]["changes"].append(name)
    manifest.write_text(json.dumps(doc))
    return run


@pytest.mark.parametrize("command", [
    ["trace", "{run}", "--episode", "10", "--limit", "5"],
    ["trace", "{run}", "--episode", "10", "--format", "csv"],
    ["show", "{run}"],
    ["runs", "{run}"],
    ["why", "{run}", "--episode", "10", "at(r1,c)"],
    ["diff", "{run}", "10", "12"],
], ids=["trace", "trace-csv", "show", "runs", "why", "diff"])
def test_ctrl_c_stops_a_long_reading_command(slow_run: Path, command: list[str]) -> None:
    """Before: the query ran on to its end (the signal was seen once DuckDB gave the thread back), or
    DuckDB's own check turned the signal into an error of its own (exit 1)."""
    status, lines, cpu = ctrl_c_after_start([a.format(run=slow_run) for a in command])
    assert cpu < 3, f"{cpu:.1f} CPU s from Ctrl-C to the end"
    assert status == 130 and len(lines) == 1 and lines[0].startswith("tracelab: interrupted"), (status, lines)
