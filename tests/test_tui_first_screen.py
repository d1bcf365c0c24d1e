"""The TUI's first screen loads nothing heavy (issue 40): `tracelab tui RUN` shows the run's Episodes table,
`tracelab tui DIR` the Runs screen's catalog, with no pandas (pyarrow's converter imports it for Python
lists: the catalog's table is built from buffers), numba, torch, rerun or matplotlib in the process.
Checked in a child interpreter (this one has imported them for other tests), through textual's pilot,
waiting on the tables' state, not on time."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("pandas", "numba", "llvmlite", "torch", "rerun", "matplotlib", "scipy", "gymnasium")

CHILD = """
import asyncio, json, sys
sys.path.insert(0, sys.argv[1])
from tui_helpers import episodes_ready, loaded, wait_for
from tracelab.viewers.tui.app import TracelabApp
from tracelab.viewers.tui.lazy_table import LazyTable
heavy = json.loads(sys.argv[2])

async def first_screen(path, table_id, ready):
    app = TracelabApp([path])
    async with app.run_test(size=(120, 40)) as pilot:
        table = await ready(app, pilot, table_id)
        print(json.dumps({"screen": type(app.screen).__name__, "rows": table.count,
                          "loaded": [m for m in heavy if m in sys.modules]}), flush=True)

async def episodes(app, pilot, table_id):
    return await episodes_ready(app, pilot)

async def catalog(app, pilot, table_id):
    table = app.screen.query_one(table_id, LazyTable)
    await wait_for(pilot, lambda: loaded(table) and table.count > 0, timeout=120)
    return table

asyncio.run(first_screen(sys.argv[3], "#ep-table", episodes))
asyncio.run(first_screen(sys.argv[4], "#runs-table", catalog))
"""


def test_the_first_screen_is_drawn_without_heavy_packages() -> None:
    out = subprocess.run([sys.executable, "-c", CHILD, str(ROOT / "tests"), json.dumps(HEAVY),
                          str(ROOT / "sample_runs" / "advanced"), str(ROOT / "sample_runs")],
                         env={**os.environ, "TEXTUAL_ANIMATIONS": "none"}, cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    run, runs = (json.loads(line) for line in out.stdout.splitlines())
    assert run["screen"] == "RunScreen" and run["rows"] == 3, run        # the run's three episodes
    assert runs["screen"] == "RunsScreen" and runs["rows"] == 5, runs    # the five sample runs
    assert run["loaded"] == [] and runs["loaded"] == [], (run, runs)
