"""The TUI's first screen loads nothing heavy (issue 40): `tracelab tui RUN` shows the run's Episodes table,
`tracelab tui DIR` the Runs screen's catalog, with no pandas (pyarrow's converter imports it for Python
lists: the catalog's table is built from buffers), numba, torch, rerun or matplotlib in the process; and
the Episodes table is drawn (the command's module imported, as `tracelab tui` does) before any other view's
module is imported (the trace's board, plots and graph,
the why tree, the SQL console, the training curves), and before numpy or pyarrow is (its rows are DuckDB's
own), the Trace view's then in the background; the Runs screen is not made under an opened run; the
table is focused first, its count read with its first page, and the imports' objects frozen (load_app).
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
DATA = ("numpy", "pyarrow")   # the trace's paging and index, the SQL console: loaded after the first screen
VIEWS = ("tracelab.viewers.tui.trace", "tracelab.viewers.board_state", "tracelab.viewers.tui.graph_side",
         "tracelab.viewers.tui.why", "tracelab.viewers.tui.sql", "tracelab.viewers.tui.training",
         "tracelab.viewers.tui.rules",
         "textual.widgets._text_area")   # the SQL editor's (tree-sitter, its themes): with the SQL view

CHILD = """
import asyncio, json, sys, time
sys.path.insert(0, sys.argv[1])
from patience import PATIENCE   # not tui_helpers: it imports the Trace view
import tracelab.commands.tui    # what `tracelab tui` runs (its screenshots' module drives every view)
import gc
from tracelab.viewers.tui import load_app
TracelabApp = load_app()        # as the command imports it: with no collections, then frozen
collectable_after_import = len(gc.get_objects())   # what a collection still walks of it: nothing
from textual.screen import Screen
from tracelab.viewers.tui.lazy_table import LazyTable
import tracelab.viewers.tui.source as source_module
focused = []        # every widget focused, in order (set_focus)
set_focus = Screen.set_focus
def _set_focus(screen, widget, *args, **kwargs):
    focused.append(getattr(widget, "id", None) or type(widget).__name__)
    return set_focus(screen, widget, *args, **kwargs)
Screen.set_focus = _set_focus
statements = []     # the statements the views ran before the Episodes table had its rows
query_readonly = source_module.query_readonly
def _query(con, sql, params=None):
    if not drawn:
        statements.append(" ".join(sql.split()))
    return query_readonly(con, sql, params)
source_module.query_readonly = _query

async def wait_for(pilot, done, timeout=PATIENCE):
    t0 = time.monotonic()
    while not done():
        await pilot.pause(0.05)
        assert time.monotonic() - t0 < timeout, "the TUI did not get there in time"

def loaded(table):
    return table.ready and table.idle and (table.count == 0 or table.cursor_row is not None)

async def episodes_ready(app, pilot):
    table = app.screen.query_one("#ep-table", LazyTable)
    await wait_for(pilot, lambda: loaded(table) and app.focused is table)
    return table
heavy, views = json.loads(sys.argv[2]), json.loads(sys.argv[5])
# which views' modules were imported before the Episodes table had its rows (its Loaded message: it is
# drawn with them), with the app's own module or later
data = json.loads(sys.argv[6])
drawn, early = [], [m for m in views if m in sys.modules]
data_early = []   # numpy, pyarrow loaded when the Episodes table had its rows
loaded_init = LazyTable.Loaded.__init__
def _loaded(message, table, count):
    if table.id == "ep-table" and not drawn:
        drawn.append(True)
        data_early.extend(m for m in data if m in sys.modules)
    loaded_init(message, table, count)
LazyTable.Loaded.__init__ = _loaded
class Watch:
    def find_spec(self, name, path=None, target=None):
        if name in views and not drawn and name not in sys.modules:
            early.append(name)
        return None
sys.meta_path.insert(0, Watch())

async def first_screen(path, table_id, ready):
    app = TracelabApp([path])
    async with app.run_test(size=(120, 40)) as pilot:
        table = await ready(app, pilot, table_id)
        if table_id == "#ep-table":   # the Trace view's modules follow in the background
            await wait_for(pilot, lambda: "tracelab.viewers.tui.trace" in sys.modules)
        print(json.dumps({"screen": type(app.screen).__name__, "rows": table.count, "views": early,
                          "data": data_early, "loaded": [m for m in heavy if m in sys.modules],
                          "screens": [type(s).__name__ for s in app.screen_stack], "focused": focused[:1],
                          "statements": statements, "collectable": collectable_after_import,
                          "frozen": gc.get_freeze_count()}), flush=True)
        focused.clear()

async def episodes(app, pilot, table_id):
    return await episodes_ready(app, pilot)

async def catalog(app, pilot, table_id):
    table = app.screen.query_one(table_id, LazyTable)
    await wait_for(pilot, lambda: loaded(table) and table.count > 0)
    return table

asyncio.run(first_screen(sys.argv[3], "#ep-table", episodes))
asyncio.run(first_screen(sys.argv[4], "#runs-table", catalog))
"""


def test_the_first_screen_is_drawn_without_heavy_packages() -> None:
    out = subprocess.run([sys.executable, "-c", CHILD, str(ROOT / "tests"), json.dumps(HEAVY),
                          str(ROOT / "sample_runs" / "advanced"), str(ROOT / "sample_runs"), json.dumps(VIEWS),
                          json.dumps(DATA)],
                         env={**os.environ, "TEXTUAL_ANIMATIONS": "none"}, cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    run, runs = (json.loads(line) for line in out.stdout.splitlines())
    assert run["screen"] == "RunScreen" and run["rows"] == 3, run        # the run's three episodes
    assert runs["screen"] == "RunsScreen" and runs["rows"] == 5, runs    # the five sample runs
    assert run["loaded"] == [] and runs["loaded"] == [], (run, runs)
    assert run["views"] == [], run
    assert run["data"] == [], run                              # the Episodes table drew without Arrow
    assert "RunsScreen" not in run["screens"], run             # made when the user goes back to it
    # the table is the first widget focused (not the tabs, then the table: each change restyles the tabs)
    assert run["focused"] == ["ep-table"], run
    # the Episodes table's count and first page in one statement (main: a count, then the page)
    table = [s for s in run["statements"] if "FROM (SELECT * FROM (SELECT episode, world" in s]
    assert len(table) == 1 and "count(*) OVER ()" in table[0] and "LIMIT 256" in table[0], run["statements"]
    # textual's, DuckDB's and the views' objects imported as `tracelab tui` does: frozen, out of every
    # garbage collection (they cost the first screen ~0.1 s of CPU in collections)
    assert run["frozen"] > 20_000 and run["collectable"] < 1_000, run


def test_the_kind_selector_is_a_training_runs_and_kept_when_the_run_is_reopened() -> None:
    """A play run's Episodes have no kind selector (not made: the first screen styles six widgets fewer); a
    training run's has it once the run is read, `e` shows its evaluation games, and the run reopened in the
    session (Esc to the Runs screen, Enter) opens with the selector on them."""
    import asyncio
    from typing import Any

    from tui_helpers import back, episodes_ready, loaded, wait_for   # here: it imports the Trace view
    from tracelab.viewers.tui.app import TracelabApp
    from tracelab.viewers.tui.lazy_table import LazyTable

    def kinds(table: Any) -> set[str]:
        return {table.row(i)["kind"] for i in range(table.count)}

    async def body(app: Any, pilot: Any) -> None:
        runs = app.screen.query_one("#runs-table", LazyTable)
        await wait_for(pilot, lambda: loaded(runs) and runs.count == 5)
        names = [runs.row(i)["name"] for i in range(runs.count)]
        runs.move_to(names.index("advanced"))
        await pilot.press("enter")
        await episodes_ready(app, pilot)
        assert not app.screen.query("#ep-kind") and not app.screen.query("#ep-kind-label")   # a play run
        await back(app, pilot)
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunsScreen")
        runs = app.screen.query_one("#runs-table", LazyTable)
        runs.move_to(names.index("base-train"))
        await pilot.press("enter")
        table = await episodes_ready(app, pilot)
        await wait_for(pilot, lambda: bool(app.screen.query("#ep-kind")) and loaded(table))
        assert table.count == 6322                              # every episode, training's and evaluation's
        await pilot.press("e")                                   # evaluation games only
        await wait_for(pilot, lambda: loaded(table) and table.count == 24)
        assert kinds(table) == {"eval"}
        await back(app, pilot)
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunsScreen")
        await pilot.press("enter")                               # the same run again: on its eval games
        table = await episodes_ready(app, pilot)
        await wait_for(pilot, lambda: loaded(table) and table.count == 24)
        assert app.screen.query_one("#ep-kind").value == "eval" and kinds(table) == {"eval"}

    async def go() -> None:
        app = TracelabApp([ROOT / "sample_runs"])
        async with app.run_test(size=(120, 40)) as pilot:
            await body(app, pilot)
    asyncio.run(go())
