"""The SQL console: one read-only statement at a time (query_readonly refuses anything that writes),
results in a lazy table, errors shown under the editor with the cursor put at their position, a history
(F3, kept between sessions: sql_history.py), the saved queries with their parameters (F2) and the
export of a result to CSV or Parquet (F4)."""
from __future__ import annotations

import re
import time
from pathlib import Path
from dataclasses import dataclass
from typing import Any

import duckdb
import pyarrow as pa
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Label, OptionList, Static, TextArea
from textual.widgets.option_list import Option

from tracelab.store.queries import SavedQuery, list_queries
from tracelab.viewers.tui.export import ExportDialog, free_name
from tracelab.viewers.tui.lazy_table import Column, LazyTable
from tracelab.viewers.tui.paging import ArrowSource
from tracelab.viewers.tui.source import RunSource, SeveralRunsSource
from tracelab.viewers.tui.sql_history import add_to_history, history_path, load_history, save_history
from tracelab.viewers.tui.shown_text import shown

KEYS = "Ctrl+R runs · F2 saved · F3 history · F4 export"
MAX_ROWS = 1_000_000   # results kept in memory (streamed; the rest is never read)
_LINE = re.compile(r"^LINE (\d+): (.*)$")


@dataclass
class SqlError:
    message: str
    line: int | None = None     # 0-based position in the statement, when the error gives one
    column: int | None = None


def locate_error(sql: str, message: str) -> SqlError:
    """DuckDB's error text ends with `LINE n: <text>` and a caret line; turn it into a position."""
    lines = message.splitlines()
    for i, text in enumerate(lines[:-1]):
        m = _LINE.match(text)
        caret = lines[i + 1]
        if not m or "^" not in caret:
            continue
        line_no = int(m[1]) - 1
        shown = m[2]
        offset = caret.index("^") - (len(text) - len(shown))
        source_lines = sql.splitlines() or [""]
        source = source_lines[min(line_no, len(source_lines) - 1)]
        if shown.startswith("..."):  # DuckDB cut the start of a long line
            start = source.find(shown[3:].rstrip(".")[:20])
            offset = max(0, start) + offset - 3
        summary = "\n".join(lines[:i]).strip()
        return SqlError(summary, line_no, max(0, min(offset, len(source))))
    return SqlError(message.strip())


def _literal(value: Any) -> str:
    """A parameter's value as typed in its box (None is `null`, as in the query file)."""
    return "null" if value is None else str(value)


class SavedQueryPicker(ModalScreen[tuple[SavedQuery, dict[str, str]] | None]):
    """Choose a saved query, then fill in its parameters (defaults shown); Enter runs it."""
    BINDINGS = [Binding("escape", "dismiss(None)", "close")]

    def __init__(self, board: bool = True, games: bool = True) -> None:
        """board: the run has a board (RuleSim's or a spec's); games: it is a run of games. The saved
        queries that need what the run is not are not offered (`-- needs board` or `-- needs games` in their header:
        `tracelab sql --query` refuses them on such a run)."""
        super().__init__()
        self.queries = [q for q in list_queries() if q.needs is None or (board if q.needs == "board" else games)]
        self.chosen: SavedQuery | None = None

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label("saved queries (Enter: choose, Esc: close)")
            yield OptionList(*[Option(Text.assemble((q.name, "bold"), f"  {q.description}"), id=q.name)
                               for q in self.queries], id="picker")
            yield Vertical(id="params")

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        self.chosen = next(q for q in self.queries if q.name == event.option.id)
        box = self.query_one("#params", Vertical)
        box.remove_children()
        if not self.chosen.params:
            self.dismiss((self.chosen, {}))
            return
        self.query_one(OptionList).display = False   # room for the parameters, at 80x24 too
        box.mount(Label(Text.assemble((self.chosen.name, "bold"), f"  {self.chosen.description}")))
        box.mount(Label("parameters (Enter: next box; in the last one it runs) · Esc closes", classes="dim"))
        for p in self.chosen.params:
            box.mount(Label(Text.assemble((p.name, "bold"), f"  {p.type}, default {_literal(p.default)}",
                                          (f" · {p.help}" if p.help else "", "dim")),
                            id=f"label-{p.name}", classes="param-label"))
            box.mount(Input(value=_literal(p.default), placeholder=p.help, id=f"param-{p.name}",
                            tooltip=f"{p.name} ({p.type}): {p.help}"))
        self.call_after_refresh(lambda: box.query(Input).first().focus())

    def on_input_submitted(self, event: Input.Submitted) -> None:
        inputs = list(self.query("#params Input").results(Input))
        if event.input is not inputs[-1]:
            inputs[inputs.index(event.input) + 1].focus()
            return
        assert self.chosen is not None
        self.dismiss((self.chosen, {i.id.removeprefix("param-"): i.value for i in inputs if i.id}))


class HistoryPicker(ModalScreen[str | None]):
    BINDINGS = [Binding("escape", "dismiss(None)", "close")]

    def __init__(self, history: list[str]) -> None:
        super().__init__()
        self.history = history

    def compose(self) -> ComposeResult:
        yield OptionList(*[Option(" ".join(q.split())[:200]) for q in reversed(self.history)])

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        self.dismiss(list(reversed(self.history))[event.option_index])


class SqlPane(Vertical):
    BINDINGS = [
        Binding("ctrl+r", "run", "run", priority=True),
        Binding("f5", "run", "run", show=False),
        Binding("f2", "saved", "saved queries"),
        Binding("f3", "history", "history"),
        Binding("f4", "export", "export"),
        Binding("ctrl+t", "focus_results", "results", show=False),
    ]

    def __init__(self, source: RunSource | SeveralRunsSource) -> None:
        """source: the run's, or several runs' (SeveralRunsSource: views with a `run` column)."""
        super().__init__()
        self.source = source
        self.history_file = history_path()
        self.history: list[str] = load_history(self.history_file)
        self._history_warned = False
        self.params: dict[str, Any] | None = None
        self.params_for: str | None = None
        self.last_error: SqlError | None = None
        self.result: pa.Table | None = None      # the result on screen (what export writes)
        self._run_id = 0                          # the latest query; older ones' results are dropped
        self._executing: int | None = None        # the query of ours on the connection now, if any

    def compose(self) -> ComposeResult:
        first = ("SELECT run, rule, count(*) AS n FROM firings GROUP BY run, rule ORDER BY run, n DESC, rule"
                 if isinstance(self.source, SeveralRunsSource) else
                 "SELECT rule, count(*) AS n FROM firings GROUP BY rule ORDER BY n DESC, rule")
        yield TextArea(first, language=None, id="sql-editor", soft_wrap=True)
        yield Static("", id="sql-error")
        table = LazyTable(id="sql-results")
        table.placeholder = "  no query run yet: Ctrl+R runs the statement above"
        yield table
        with Horizontal(classes="status"):
            yield Static(f" ready · {KEYS} · read-only", id="sql-status")

    def _remember(self, sql: str) -> None:
        """Add `sql` to the history and save it at once (the file as it is now: other consoles, open
        meanwhile, keep theirs too)."""
        self.history = add_to_history(load_history(self.history_file) or self.history, sql)
        try:
            save_history(self.history_file, self.history)
        except OSError as e:
            if not self._history_warned:     # once: the console works on without a saved history
                self._history_warned = True
                self.notify(f"SQL history not saved: {e}", severity="warning")

    def focus_default(self) -> None:
        self.editor.focus()

    @property
    def editor(self) -> TextArea:
        return self.query_one("#sql-editor", TextArea)

    @property
    def results(self) -> LazyTable:
        return self.query_one("#sql-results", LazyTable)

    @property
    def error_line(self) -> Static:
        """The query's error, over the results (empty when it ran)."""
        return self.query_one("#sql-error", Static)

    def action_run(self) -> None:
        sql = self.editor.text.strip()
        if not sql:
            return
        params = self.params if self.params_for == sql else None
        self.run_sql(sql, params)

    def run_sql(self, sql: str, params: dict[str, Any] | None = None, label: str = "") -> None:
        self._remember(sql)
        saved = self.params_for == sql   # a saved query's text: on several runs, run on each run
        # A query of ours still running is cancelled: the new one would otherwise wait behind it for
        # the connection (minutes, for a big join), and its late result would replace the new one's.
        superseded = self._interrupt_own()
        self._run_id += 1
        run_id = self._run_id
        self.last_error = None
        self.error_line.update("")
        doing = f"running {label or 'query'}… (Esc cancels)"
        self._clear_result(doing)
        self._set_status(("previous query cancelled · " if superseded else "") + doing)

        def on_connection(con: Any) -> Any:
            if run_id != self._run_id:
                return None                 # superseded before it began: never run it
            self._executing = run_id        # now ours is the statement an interrupt() stops
            try:
                return self.source.fetch(con, sql, params, saved, MAX_ROWS)
            finally:
                self._executing = None

        def work() -> None:
            # an older query of ours that had the connection but had not begun when it was interrupted
            # missed that interrupt: interrupt it until it gives the connection up
            while run_id == self._run_id and (self._executing or run_id) < run_id:
                self.source.con.interrupt()
                time.sleep(0.05)
            try:
                table = self.source.call(on_connection)
            except duckdb.InterruptException:  # Esc, or a newer query: a cancel, never an error to fix
                self.app.call_from_thread(self._cancelled, run_id, label)
                return
            except Exception as e:  # noqa: BLE001 - every error is shown inline
                self.app.call_from_thread(self._failed, run_id, sql, str(e))
                return
            self.app.call_from_thread(self._show, run_id, table, label)

        self.run_worker(work, thread=True, group="sql", exit_on_error=False)

    def _interrupt_own(self) -> bool:
        """Interrupt this console's statement if it is the one on the connection now (never another
        view's query); True if one was interrupted."""
        if self._executing is None:
            return False
        self.source.con.interrupt()
        return True

    def _clear_result(self, placeholder: str) -> None:
        """Empty the results table (a failed or cancelled query has no result: the previous one must not
        stay under its message), saying why in its first row."""
        self.result = None
        table = self.results
        table.placeholder = f"  {placeholder}"
        table.set_source(None)

    def _set_status(self, text: str) -> None:
        self.query_one("#sql-status", Static).update(f" {text} · {KEYS}")

    def _show(self, run_id: int, table: Any, label: str) -> None:
        if run_id != self._run_id or table is None:
            return  # superseded by a newer query
        self.result = table
        columns = [Column(name, name, None) for name in table.column_names]
        self.results.set_source(ArrowSource(table), columns)
        capped = " (first rows only)" if table.num_rows >= MAX_ROWS else ""
        self._set_status(f"{label + ': ' if label else ''}{table.num_rows:,} row(s){capped}")

    def _cancelled(self, run_id: int, label: str) -> None:
        if run_id != self._run_id:
            return
        self._clear_result("cancelled: no result")
        self._set_status(f"{label + ': ' if label else ''}cancelled")

    def _failed(self, run_id: int, sql: str, message: str) -> None:
        if run_id != self._run_id:
            return
        err = locate_error(sql, message)
        self.last_error = err
        where = f" (line {err.line + 1}, column {err.column + 1})" if err.line is not None else ""
        self.error_line.update(shown(err.message + where, "bold"))
        self._clear_result("no result: the query failed (the error is above)")
        self._set_status("error · fix the query and Ctrl+R")
        if err.line is not None and self.editor.text.strip() == sql:
            self.editor.move_cursor((err.line, err.column))
            self.editor.move_cursor((err.line, err.column + 1), select=True)
            self.editor.focus()

    def action_saved(self) -> None:
        def chosen(result: tuple[SavedQuery, dict[str, str]] | None) -> None:
            if result is None:
                return
            query, given = result
            try:
                params = query.bind(given)
            except (KeyError, ValueError) as e:
                self.error_line.update(Text(str(e).strip("'\""), style="bold"))
                return
            self.editor.text = query.sql
            self.params, self.params_for = params or None, query.sql.strip()
            self.run_sql(query.sql.strip(), params or None, label=query.name)

        self.app.push_screen(SavedQueryPicker(board=self.source.has_board, games=self.source.games), chosen)

    def action_history(self) -> None:
        if not self.history:
            self.notify("no queries run yet")
            return

        def chosen(sql: str | None) -> None:
            if sql is not None:
                self.editor.text = sql
                self.editor.focus()

        self.app.push_screen(HistoryPicker(self.history), chosen)

    def action_export(self) -> None:
        if self.result is None:
            self.notify("no result to export: run a query first (Ctrl+R)")
            return
        dialog = ExportDialog(self.result, free_name(f"{self.source.path.name}-sql"), "SQL result")

        def written(path: Path | None) -> None:
            if path is not None:
                self.notify(f"exported {dialog.rows_written:,} row(s) to {path}")

        self.app.push_screen(dialog, written)

    def action_focus_results(self) -> None:
        self.results.focus()
