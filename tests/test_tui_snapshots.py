"""Snapshot tests of the TUI's main screens on the sample runs: each screen, headless at 120x34, compared
with its golden file in tests/data/tui_snapshots/ (tests/tui_snapshot.py says what a snapshot holds).
After an intended change: TRACELAB_UPDATE_SNAPSHOTS=1 .venv/bin/python -m pytest tests/test_tui_snapshots.py
and look at the diff of the golden files before committing them."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest
from patience import PATIENCE
from tui_helpers import episodes_ready, has_rows, loaded, pick_saved_query, run_app, trace_at, wait_for

from tracelab.viewers.tui.lazy_table import LazyTable
from tracelab.viewers.tui.trace import TracePane
from tui_snapshot import check_snapshot, screen_cells

ROOT = Path(__file__).resolve().parent.parent
SIZE = (120, 34)


# Workers that re-read a run or a folder on a timer: on a loaded machine one of them is running at most
# moments, so the screen staying the same is what says they changed nothing.
PERIODIC = {"catalog", "run-status", "episodes-poll", "trace-follow"}


async def settled(app: Any, pilot: Any) -> None:
    """Wait until no worker runs (but the periodic ones) and the screen stays the same over a few repaints;
    stop cursors blinking."""
    for widget in app.screen.query("Input, TextArea"):
        widget.cursor_blink = False
    t0, last, same = time.monotonic(), None, 0
    while same < 3:
        await pilot.pause(0.1)
        busy = any(w.is_running and w.group not in PERIODIC for w in app.workers)
        now = screen_cells(app)
        same = same + 1 if (now == last and not busy) else 0
        last = now
        if time.monotonic() - t0 > PATIENCE:
            raise AssertionError("the screen did not settle")


class Snapshots:
    def __init__(self, app: Any, pilot: Any, prefix: str) -> None:
        self.app, self.pilot, self.prefix, self.failures = app, pilot, prefix, []

    async def take(self, name: str) -> None:
        await settled(self.app, self.pilot)
        diff = check_snapshot(f"{self.prefix}-{name}", self.app)
        if diff:
            self.failures.append(f"== {self.prefix}-{name}\n{diff}")


@pytest.fixture(autouse=True)
def at_repo_root(monkeypatch: pytest.MonkeyPatch) -> None:
    """Runs are opened by their path relative to the checkout, so no screen shows where it is."""
    monkeypatch.chdir(ROOT)


def test_runs_screen_snapshot() -> None:
    failures: list[str] = []

    async def body(app: Any, pilot: Any) -> None:
        table = app.screen.query_one(LazyTable)
        await wait_for(pilot, lambda: loaded(table) and table.count == 5)
        shots = Snapshots(app, pilot, "runs")
        await shots.take("catalog")
        failures.extend(shots.failures)
    run_app([Path("sample_runs")], body, SIZE)
    if failures:
        pytest.fail("\n".join(failures), pytrace=False)


@pytest.mark.parametrize("run", ["base", "advanced", "base-train"])
def test_run_screens_snapshots(run: str) -> None:
    """Episodes, Trace with Board, Why, Rules, SQL console (a saved query's result) and, of the training
    run, Training."""
    failures: list[str] = []

    async def body(app: Any, pilot: Any) -> None:
        shots = Snapshots(app, pilot, run)
        await episodes_ready(app, pilot)
        await shots.take("episodes")

        await pilot.press("enter")                                   # the first episode's trace
        pane = app.screen.query_one(TracePane)
        await wait_for(pilot, lambda: pane.filter is not None and loaded(pane.table))
        if pane.table.count == 0:                                     # a training episode: not traced,
            await pilot.press("right_square_bracket")                 # so the first evaluation game
            await wait_for(pilot, lambda: has_rows(pane.table))
        jumps = pane.jumps
        pane.query_one("#tr-goto").value = "10"
        await pilot.press("g", "enter")                               # a step with a board worth seeing
        await wait_for(pilot, lambda: pane.jumps > jumps and loaded(pane.table))
        await wait_for(pilot, lambda: pane.board is not None and pane.board.board is not None
                       and pane.board.step == 10)
        await shots.take("trace")

        await pilot.press("w")                                        # why the change at the cursor
        why = app.screen.panes["why"]
        await wait_for(pilot, lambda: why.is_attached and why.query_one("Tree").root.data is not None)
        await shots.take("why")

        await pilot.press("4")
        rules = app.screen.panes["rules"]
        await wait_for(pilot, lambda: rules.is_attached and loaded(rules.query_one(LazyTable)))
        await wait_for(pilot, lambda: "never fired" in app.screen.query_one("#rules-status").render().plain)
        await shots.take("rules")

        await pilot.press("5")
        sql = app.screen.panes["sql"]
        await wait_for(pilot, lambda: sql.is_attached and app.focused is sql.editor)
        await pick_saved_query(app, pilot, "firings_per_episode", str(pane.filter.episode))
        results = sql.query_one(LazyTable)
        await wait_for(pilot, lambda: has_rows(results)
                       and app.focused is sql.editor)
        await pilot.press("escape")                                   # from the editor to the results
        await wait_for(pilot, lambda: app.focused is results)
        await shots.take("sql")

        if run == "base-train":   # a play run (no metrics) has no Training view
            await pilot.press("6")
            await wait_for(pilot, lambda: app.screen.panes["training"].is_attached)
            await wait_for(pilot, lambda: "reading metrics" not in
                           app.screen.query_one("#train-status").render().plain)
            await shots.take("training")
        failures.extend(shots.failures)
    run_app([Path("sample_runs") / run], body, SIZE)
    if failures:
        pytest.fail("\n".join(failures), pytrace=False)


@pytest.mark.parametrize("size", [(80, 24), SIZE])
def test_run_without_a_board_snapshots(size: tuple[int, int]) -> None:
    """sample_runs/supply-chain (a reasoning run): Episodes, Trace at t=3 with the atoms true then and the
    graph around the cursor's atom beside it (at 80x24 shown by `b`), Why, Rules and the SQL console."""
    failures: list[str] = []

    async def body(app: Any, pilot: Any) -> None:
        shots = Snapshots(app, pilot, "supply-chain" if size == SIZE else f"supply-chain-{size[0]}x{size[1]}")
        await episodes_ready(app, pilot)
        await shots.take("episodes")

        pane = await trace_at(app, pilot, 3)
        side = pane.side
        if not side.display:
            await pilot.press("b")
        await wait_for(pilot, lambda: side.display and side.atoms is not None and side.atoms.t == 3
                       and side.hood is not None and side.hood.t == 3 and loaded(side.table))
        await shots.take("trace")

        await pilot.press("w")
        why = app.screen.panes["why"]
        await wait_for(pilot, lambda: why.is_attached and why.query_one("Tree").root.data is not None)
        await shots.take("why")

        await pilot.press("4")
        rules = app.screen.panes["rules"]
        await wait_for(pilot, lambda: rules.is_attached and loaded(rules.query_one(LazyTable)))
        await wait_for(pilot, lambda: "never fired" in app.screen.query_one("#rules-status").render().plain)
        await shots.take("rules")

        await pilot.press("5")
        sql = app.screen.panes["sql"]
        await wait_for(pilot, lambda: sql.is_attached and app.focused is sql.editor)
        await pick_saved_query(app, pilot, "firings_per_episode", "0")
        results = sql.query_one(LazyTable)
        await wait_for(pilot, lambda: has_rows(results)
                       and app.focused is sql.editor)
        await pilot.press("escape")
        await wait_for(pilot, lambda: app.focused is results)
        await shots.take("sql")
        failures.extend(shots.failures)
    run_app([Path("sample_runs") / "supply-chain"], body, size)
    if failures:
        pytest.fail("\n".join(failures), pytrace=False)


def test_trace_beside_the_board_at_80x24_snapshot() -> None:
    """80x24, the floor: the advanced run's trace at t=10 with the board shown by `b`, every column of the
    trace narrowed to fit beside it (the rule column readable, no sideways scroll)."""
    failures: list[str] = []

    async def body(app: Any, pilot: Any) -> None:
        shots = Snapshots(app, pilot, "advanced-80x24")
        await episodes_ready(app, pilot)
        await pilot.press("enter")
        pane = app.screen.query_one(TracePane)
        await wait_for(pilot, lambda: pane.filter is not None and has_rows(pane.table))
        await wait_for(pilot, lambda: app.focused is pane.table)
        jumps = pane.jumps
        pane.query_one("#tr-goto").value = "10"
        await pilot.press("g", "enter")
        await wait_for(pilot, lambda: pane.jumps > jumps and loaded(pane.table))
        await pilot.press("b")
        await wait_for(pilot, lambda: pane.side_box.display and pane.board.board is not None
                       and pane.board.step == 10)
        await shots.take("trace")
        failures.extend(shots.failures)
    run_app([Path("sample_runs") / "advanced"], body, (80, 24))
    if failures:
        pytest.fail("\n".join(failures), pytrace=False)
