"""LazyTable (viewers/tui/lazy_table.py) and its worker threads, headless (textual's run_test + Pilot): a table
in a tab not shown is prepared without its worker reading the widget, and a source that fails to prepare is
shown as its error in the table, not as an empty table."""
from __future__ import annotations

import asyncio
import os
import threading
from pathlib import Path

os.environ["TEXTUAL_ANIMATIONS"] = "none"

import pyarrow as pa  # noqa: E402
from textual.app import App, ComposeResult  # noqa: E402
from textual.geometry import Region  # noqa: E402
from textual.widgets import Static, TabbedContent, TabPane  # noqa: E402

from tracelab.viewers.tui.lazy_table import Column, LazyTable  # noqa: E402
from tracelab.viewers.tui.paging import ArrowSource, QuerySource  # noqa: E402
from tracelab.viewers.tui.source import RunSource  # noqa: E402
from tui_helpers import shown_once, wait_for  # noqa: E402

ADVANCED = Path(__file__).resolve().parent.parent / "sample_runs" / "advanced"


class GeometryWatchedTable(LazyTable):
    """A LazyTable that notes which threads read where it is on the screen (textual's `region`, which its
    size, content region and scrollable region are all read from)."""

    def __init__(self, columns: list[Column]) -> None:
        super().__init__(columns)
        self.geometry_readers: set[threading.Thread] = set()

    @property
    def region(self) -> Region:
        self.geometry_readers.add(threading.current_thread())
        return super().region


class TabsApp(App[None]):
    """A table in the second of two tabs: `shown` chooses which tab the app opens on."""

    def __init__(self, table: LazyTable, shown: str) -> None:
        super().__init__()
        self.table, self.shown = table, shown

    def compose(self) -> ComposeResult:
        with TabbedContent(initial=self.shown):
            with TabPane("other", id="other"):
                yield Static("the table is in the other tab")
            with TabPane("table", id="table"):
                yield self.table


def test_a_table_in_a_hidden_tab_is_prepared_without_its_worker_reading_the_widget() -> None:
    """The conditions of a run reopened in the session with its trace left on a view not shown (the trace's
    table 0x0 in a hidden tab): the prepare worker read the widget's size, and textual, asked where a
    hidden widget is, laid out the whole screen in that thread. It raised LookupError there (textual's
    `active_app` is not set in worker threads) and the trace opened empty with that as its error, or
    raced the UI thread's own layout. Only the UI thread reads the table's geometry now."""
    table = GeometryWatchedTable([Column("n", "n")])

    async def go() -> None:
        app = TabsApp(table, shown="other")
        async with app.run_test(size=(80, 24)) as pilot:
            await pilot.pause()
            assert table.size.area == 0                       # hidden: laid out nowhere
            table.geometry_readers.clear()
            table.set_source(ArrowSource(pa.table({"n": list(range(1000))})), cursor=600)
            await wait_for(pilot, lambda: table.ready)
            assert table.error is None and table.count == 1000 and table.cursor == 600
            assert table.row(600) == {"n": 600}               # the cursor's page came with the count
            assert table.geometry_readers == {threading.current_thread()}, table.geometry_readers
    asyncio.run(go())


def test_a_source_that_fails_to_prepare_shows_its_error_in_the_table() -> None:
    """A source whose count fails (here a column the run does not have) leaves no rows: the table says why
    on its first line, in the error's own words, rather than drawing an empty table."""
    source = RunSource(ADVANCED)
    table = LazyTable([Column("episode", "episode")])

    async def go() -> None:
        app = TabsApp(table, shown="table")
        async with app.run_test(size=(80, 24)) as pilot:
            table.set_source(QuerySource(source, "SELECT no_such_column FROM episodes", "episode"))
            await wait_for(pilot, lambda: table.ready)
            assert table.count == 0 and table.error is not None and "no_such_column" in table.error
            first_line = table.error.splitlines()[0]
            text = await shown_once(app, pilot, lambda s: first_line[:60] in s)
            assert first_line[:60] in text and "(no rows)" not in text
    try:
        asyncio.run(go())
    finally:
        source.close()
