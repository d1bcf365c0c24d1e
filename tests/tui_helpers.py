"""Driving the TUI headless in tests (textual's run_test + Pilot): waiting for a state, a loaded lazy table,
an app run around a test body. Shared by test_tui.py and test_tui_snapshots.py."""
from __future__ import annotations

import asyncio
import atexit
import html
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from patience import PATIENCE

os.environ["TEXTUAL_ANIMATIONS"] = "none"
# the SQL console keeps its history in the user's state folder: never the real one in tests
_STATE = tempfile.mkdtemp(prefix="tracelab-test-state-")
os.environ["XDG_STATE_HOME"] = _STATE
atexit.register(shutil.rmtree, _STATE, ignore_errors=True)

from tracelab.viewers.tui.app import TracelabApp  # noqa: E402
from tracelab.viewers.tui.graph_side import GraphSide  # noqa: E402
from tracelab.viewers.tui.lazy_table import LazyTable  # noqa: E402
from tracelab.viewers.tui.trace import TracePane  # noqa: E402

TESTS = Path(__file__).resolve().parent


async def wait_for(pilot: Any, done: Callable[[], bool], timeout: float = PATIENCE) -> None:
    t0 = time.monotonic()
    while not done():
        await pilot.pause(0.05)
        if time.monotonic() - t0 > timeout:
            raise AssertionError("the TUI did not get there in time")


def loaded(table: LazyTable) -> bool:
    return table.ready and table.idle and (table.count == 0 or table.cursor_row is not None)


def has_rows(table: LazyTable) -> bool:
    """Loaded with rows; a table that loaded without rows and with an error fails the test at once, saying
    the error, instead of waiting out PATIENCE for rows that cannot come."""
    assert not (table.ready and table.error and not table.count), f"the table failed to load: {table.error}"
    return table.count > 0 and loaded(table)


async def back(app: Any, pilot: Any) -> None:
    """Esc as "back one view", pressed once no query the user waits on runs on the open run's connection:
    while one runs (a view still loading), Esc cancels it instead and stays (RunScreen.action_cancel_or_back),
    and a test waiting for the view it meant to reach would wait out PATIENCE. Background work (the trace's
    warm-up, the board read for Enter) does not hold Esc back."""
    await wait_for(pilot, lambda: not (getattr(app.screen, "source", None) and app.screen.source.foreground_busy))
    await pilot.press("escape")


async def episodes_ready(app: Any, pilot: Any) -> LazyTable:
    """The run's Episodes table loaded and focused: keys pressed before the focus lands (the app sets it
    after a refresh, late on a loaded machine) would go nowhere."""
    table = app.screen.query_one("#ep-table", LazyTable)
    await wait_for(pilot, lambda: loaded(table) and app.focused is table)
    return table


async def trace_at(app: Any, pilot: Any, t: int) -> TracePane:
    """From the Episodes view: the first episode's trace, gone to timestep t (`g`) and loaded there."""
    await pilot.press("enter")
    pane = app.screen.query_one(TracePane)
    await wait_for(pilot, lambda: pane.filter is not None and has_rows(pane.table))
    jumps = pane.jumps
    pane.query_one("#tr-goto").value = str(t)
    await pilot.press("g", "enter")
    await wait_for(pilot, lambda: pane.jumps > jumps and loaded(pane.table))
    return pane


async def open_trace_at(app: Any, pilot: Any, t: int) -> tuple[TracePane, GraphSide]:
    """A run without a board: its first episode's trace at timestep t, with the atoms and the graph
    beside it loaded."""
    await episodes_ready(app, pilot)
    pane = await trace_at(app, pilot, t)
    side = pane.query_one(GraphSide)
    await wait_for(pilot, lambda: side.atoms is not None and side.atoms.t == t and side.hood is not None
                   and loaded(side.table))
    return pane, side


def run_app(paths: list[Path], body: Callable[[Any, Any], Any], size: tuple[int, int] = (80, 24)) -> None:
    async def go() -> None:
        app = TracelabApp(paths)
        async with app.run_test(size=size) as pilot:
            await body(app, pilot)
    asyncio.run(go())


async def run_query(pilot: Any, sql: Any, statement: str) -> None:
    """In the SQL console `sql` (a SqlPane): STATEMENT in the editor, then Ctrl+R."""
    sql.editor.text = statement
    sql.editor.focus()
    await pilot.press("ctrl+r")


async def pick_saved_query(app: Any, pilot: Any, name: str, value: str) -> None:
    """In the SQL console: F2, the saved query NAME, VALUE for its one parameter, Enter (it runs)."""
    await pilot.press("f2")
    await wait_for(pilot, lambda: type(app.screen).__name__ == "SavedQueryPicker")
    picker = app.screen
    names = [q.name for q in picker.queries]
    picker.query_one("OptionList").highlighted = names.index(name)
    await pilot.press("enter")
    await wait_for(pilot, lambda: len(picker.query("Input")) == 1)
    picker.query_one("Input").value = value
    await pilot.press("enter")


async def shown(app: Any, pilot: Any) -> str:
    """What the screen shows once it has repainted, as plain text lines (from textual's SVG screenshot)."""
    await pilot.pause()
    return svg_text(app.export_screenshot())


def svg_text(svg: str) -> str:
    """A textual SVG screenshot's text, line by line."""
    lines: dict[float, list[tuple[float, str]]] = defaultdict(list)
    for x, y, text in re.findall(r'<text[^>]*x="([\d.]+)" y="([\d.]+)"[^>]*>([^<]*)</text>', svg):
        lines[float(y)].append((float(x), html.unescape(text).replace("\xa0", " ")))
    return "\n".join("".join(t for _, t in sorted(parts)) for _, parts in sorted(lines.items()))


async def shown_once(app: Any, pilot: Any, ready: Callable[[str], bool], timeout: float = PATIENCE) -> str:
    """The screen's text once `ready` holds for it (a table's rows are painted a frame after they load),
    or the last text seen after `timeout` seconds (the caller's assertion then says what is missing)."""
    t0 = time.monotonic()
    text = await shown(app, pilot)
    while not ready(text) and time.monotonic() - t0 < timeout:
        await pilot.pause(0.05)
        text = await shown(app, pilot)
    return text


@contextmanager
def live_writer(mode: str, tmp_path: Path) -> Iterator[tuple[Path, subprocess.Popen]]:
    """A run another process is writing (tests/tui_writer_proc.py MODE), from its first flush on, and
    that process (to stop it as a user would)."""
    run, stop = tmp_path / f"{mode}-live", tmp_path / "stop"
    proc = subprocess.Popen([sys.executable, str(TESTS / "tui_writer_proc.py"), mode, str(run),
                             str(stop)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip()
        yield run, proc
    finally:
        stop.touch()
        proc.wait(timeout=PATIENCE)


@contextmanager
def live_run(mode: str, tmp_path: Path) -> Iterator[Path]:
    """A run another process is writing (tests/tui_writer_proc.py MODE), from its first flush on."""
    with live_writer(mode, tmp_path) as (run, _):
        yield run
