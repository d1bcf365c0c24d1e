"""The SQL console: one read-only statement at a time (query_readonly refuses anything that writes),
results in a lazy table, errors shown under the editor with the cursor put at their position, a history
(F3) and the saved queries with their parameters (F2)."""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import duckdb
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Label, OptionList, Static, TextArea
from textual.widgets.option_list import Option

from tracelab.store.queries import SavedQuery, list_queries
from tracelab.store.reader import fetch_arrow, query_readonly
from tracelab.viewers.tui.lazy_table import Column, LazyTable
from tracelab.viewers.tui.paging import ArrowSource
from tracelab.viewers.tui.source import RunSource

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


class SavedQueryPicker(ModalScreen[tuple[SavedQuery, dict[str, str]] | None]):
    """Choose a saved query, then fill in its parameters (defaults shown); Enter runs it."""
    BINDINGS = [Binding("escape", "dismiss(None)", "close")]
    DEFAULT_CSS = """
    SavedQueryPicker { align: center middle; }
    SavedQueryPicker > Vertical { width: 90%; max-width: 100; height: auto; max-height: 90%;
                                  border: round $accent; background: $panel; padding: 0 1; }
    SavedQueryPicker OptionList { height: auto; max-height: 12; }
    SavedQueryPicker Input { margin: 0; }
    """

    def __init__(self) -> None:
        super().__init__()
        self.queries = list_queries()
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
        box.mount(Label(f"{self.chosen.name}: parameters (Enter in the last one runs it)"))
        for p in self.chosen.params:
            default = "null" if p.default is None else str(p.default)
            box.mount(Input(value=default, placeholder=p.help, id=f"param-{p.name}",
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
    DEFAULT_CSS = """
    HistoryPicker { align: center middle; }
    HistoryPicker OptionList { width: 90%; max-width: 110; height: auto; max-height: 80%;
                               border: round $accent; }
    """

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
        Binding("ctrl+t", "focus_results", "results", show=False),
    ]
    DEFAULT_CSS = """
    SqlPane TextArea { height: 6; }
    SqlPane #sql-error { color: $error; height: auto; max-height: 6; }
    """

    def __init__(self, source: RunSource) -> None:
        super().__init__()
        self.source = source
        self.history: list[str] = []
        self.params: dict[str, Any] | None = None
        self.params_for: str | None = None
        self.last_error: SqlError | None = None

    def compose(self) -> ComposeResult:
        yield TextArea("SELECT rule, count(*) AS n FROM firings GROUP BY rule ORDER BY n DESC, rule",
                       language=None, id="sql-editor", soft_wrap=True)
        yield Static("", id="sql-error")
        yield LazyTable(id="sql-results")
        with Horizontal(classes="status"):
            yield Static(" Ctrl+R runs · F2 saved queries · F3 history · read-only", id="sql-status")

    def focus_default(self) -> None:
        self.query_one(TextArea).focus()

    @property
    def editor(self) -> TextArea:
        return self.query_one(TextArea)

    def action_run(self) -> None:
        sql = self.editor.text.strip()
        if not sql:
            return
        params = self.params if self.params_for == sql else None
        self.run_sql(sql, params)

    def run_sql(self, sql: str, params: dict[str, Any] | None = None, label: str = "") -> None:
        if not self.history or self.history[-1] != sql:
            self.history.append(sql)
        self.query_one("#sql-error", Static).update("")
        self.last_error = None
        status = self.query_one("#sql-status", Static)
        status.update(f" running {label or 'query'}… (Esc cancels)")

        def work() -> None:
            try:
                table = self.source.call(lambda con: fetch_arrow(query_readonly(con, sql, params), MAX_ROWS))
            except duckdb.InterruptException:  # Esc (RunScreen: the source's interrupt()); not an error
                self.app.call_from_thread(self._cancelled, label)
                return
            except Exception as e:  # noqa: BLE001 - every error is shown inline
                self.app.call_from_thread(self._failed, sql, str(e))
                return
            self.app.call_from_thread(self._show, table, label)

        self.run_worker(work, thread=True, group="sql", exclusive=True, exit_on_error=False)

    def _show(self, table: Any, label: str) -> None:
        columns = [Column(name, name, None) for name in table.column_names]
        self.query_one(LazyTable).set_source(ArrowSource(table), columns)
        capped = " (first rows only)" if table.num_rows >= MAX_ROWS else ""
        self.query_one("#sql-status", Static).update(
            f" {label + ': ' if label else ''}{table.num_rows:,} row(s){capped} · Ctrl+R runs · F2 saved · F3 history")

    def _cancelled(self, label: str) -> None:
        self.query_one("#sql-status", Static).update(
            f" {label + ': ' if label else ''}cancelled · Ctrl+R runs · F2 saved · F3 history")

    def _failed(self, sql: str, message: str) -> None:
        err = locate_error(sql, message)
        self.last_error = err
        where = f" (line {err.line + 1}, column {err.column + 1})" if err.line is not None else ""
        self.query_one("#sql-error", Static).update(Text(err.message + where, style="bold"))
        self.query_one("#sql-status", Static).update(" error · fix the query and Ctrl+R")
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
                self.query_one("#sql-error", Static).update(Text(str(e).strip("'\""), style="bold"))
                return
            self.editor.text = query.sql
            self.params, self.params_for = params or None, query.sql.strip()
            self.run_sql(query.sql.strip(), params or None, label=query.name)

        self.app.push_screen(SavedQueryPicker(), chosen)

    def action_history(self) -> None:
        if not self.history:
            self.notify("no queries run yet")
            return

        def chosen(sql: str | None) -> None:
            if sql is not None:
                self.editor.text = sql
                self.editor.focus()

        self.app.push_screen(HistoryPicker(self.history), chosen)

    def action_focus_results(self) -> None:
        self.query_one(LazyTable).focus()
