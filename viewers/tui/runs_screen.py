"""The Runs screen: the run catalog (tracelab.store.catalog), refreshed every few seconds while runs grow.
Enter opens a run; space marks runs and `c` opens the marked ones together, the first with the others'
curves overlaid in its Training view (as `tracelab tui RUN RUN ...` does)."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.screen import Screen
from textual.widgets import Static

from tracelab.store.catalog import RunSummary, catalog_table, list_runs
from tracelab.viewers.tui.colours import FALSE, PARTIAL, TRUE, UNKNOWN
from tracelab.viewers.tui.keybar import KeyBar
from tracelab.viewers.tui.lazy_table import Column, LazyTable
from tracelab.viewers.tui.paging import ArrowSource

REFRESH_S = 2.0
STATUS_COLOURS = {"running": PARTIAL, "finished": TRUE, "failed": FALSE, "crashed": FALSE,
                  "interrupted": UNKNOWN, "unreadable": FALSE}


def _status(row: dict) -> Text:
    return Text(row["status"], style=STATUS_COLOURS.get(row["status"], ""))


RUN_COLUMNS = [
    Column("name", "run", None, max_width=24),
    Column("status", "status", 11, render=_status),
    Column("episodes", "eps", 6, align="right"),
    Column("rows", "rows", 10, align="right", render=lambda r: f"{r['rows']:,}" if r["rows"] is not None else ""),
    Column("size", "size", 9, align="right"),
    Column("started", "started", 19),
    Column("scenario", "scenario", None, max_width=12),
    Column("command", "command", None, max_width=60),
]


class RunsScreen(Screen):
    BINDINGS = [Binding("enter", "open", "open run"), Binding("space", "mark", "mark"),
                Binding("c", "compare", "compare marked"), Binding("r", "refresh", "refresh")]

    def __init__(self, roots: list[Path]) -> None:
        super().__init__()
        self.roots = roots
        self.runs: list[RunSummary] = []
        self.marked: list[str] = []   # paths of the marked runs, in the order they were marked

    def compose(self) -> ComposeResult:
        yield Static(f" tracelab runs in {', '.join(map(str, self.roots))}", id="title", classes="title")
        mark = Column("path", "", 1, render=lambda r: Text("✓", style=TRUE) if r["path"] in self.marked else "")
        yield LazyTable([mark, *(replace(c) for c in RUN_COLUMNS)], id="runs-table")
        yield Static("", id="runs-status", classes="status")
        yield KeyBar()

    @property
    def table(self) -> LazyTable:
        return self.query_one("#runs-table", LazyTable)

    def on_mount(self) -> None:
        self.table.focus()
        self.set_interval(REFRESH_S, self._tick)

    def on_screen_resume(self) -> None:
        if self.is_current:  # shown (first, or back from a run): read the catalog now
            self.action_refresh()

    def _tick(self) -> None:
        reading = any(w.group == "catalog" and w.is_running for w in self.workers)
        if self.is_current and not reading:  # not while a run is open over it, nor over a slow read
            self.action_refresh()

    def action_refresh(self) -> None:
        self.run_worker(self._load, thread=True, group="catalog", exclusive=True, exit_on_error=False)

    def _load(self) -> None:
        runs = list_runs(self.roots)
        self.app.call_from_thread(self._show, runs)

    def _show(self, runs: list[RunSummary], redraw: bool = False) -> None:
        changed = [r.as_row() for r in runs] != [r.as_row() for r in self.runs]
        self.runs = runs
        self.marked = [p for p in self.marked if p in {str(r.path) for r in runs}]   # runs that went away
        table = self.table
        if changed or redraw or not table.ready:
            rows = [r.as_row() for r in runs]
            table.set_source(ArrowSource(catalog_table(rows)),
                             cursor=table.cursor)
        live = sum(r.status == "running" for r in runs)
        marked = (f"{len(self.marked)} marked, c compares them" if self.marked else "space marks runs to compare")
        self.query_one("#runs-status", Static).update(
            f" {len(runs)} run(s), {live} running · Enter opens · {marked} · refreshes every {REFRESH_S:g} s")

    def action_mark(self) -> None:
        table = self.table
        if not 0 <= table.cursor < len(self.runs):
            return
        path = str(self.runs[table.cursor].path)
        if path in self.marked:
            self.marked.remove(path)
        else:
            self.marked.append(path)
        self._show(self.runs, redraw=True)
        if table.cursor + 1 < len(self.runs):
            table.move_to(table.cursor + 1)   # mark the next one with the next space

    def action_compare(self) -> None:
        if len(self.marked) < 2:
            self.notify("mark two runs or more with space, then c: the first opens with the others' curves "
                        "overlaid in its Training view")
            return
        first, *others = map(Path, self.marked)
        self.app.show_run(first, others)  # type: ignore[attr-defined]

    def action_open(self) -> None:
        table = self.table
        if 0 <= table.cursor < len(self.runs):
            self.app.show_run(self.runs[table.cursor].path)  # type: ignore[attr-defined]

    def on_lazy_table_row_selected(self, event: LazyTable.RowSelected) -> None:
        event.stop()
        self.action_open()
