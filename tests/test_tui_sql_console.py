"""The TUI's SQL console as a new user meets it (issue 27 §6, and §10's export): it opens at once and says
it is idle, a failed or cancelled query leaves no stale result under its message, a new query cancels
the running one, the saved queries' parameters are labelled, the history outlives the app (in a capped
file of the state folder, read and written safely), and F4 exports the result to CSV or Parquet without
replacing a file unasked. Headless, through textual's Pilot, on sample_runs/advanced."""
from __future__ import annotations

import json
import os
import stat
import threading
from pathlib import Path
from typing import Any

import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from tracelab.viewers.tui.lazy_table import LazyTable  # noqa: E402
from tracelab.viewers.tui.source import RunSource  # noqa: E402
from tracelab.viewers.tui.sql import SqlPane  # noqa: E402
from tracelab.viewers.tui.sql_history import HISTORY_CAP, load_history  # noqa: E402
from patience import PATIENCE  # noqa: E402
from tui_helpers import episodes_ready, loaded, run_app, run_query, shown, shown_once, wait_for  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
ADVANCED = ROOT / "sample_runs" / "advanced"
ENDLESS = "SELECT sum(a.range * b.range) FROM range(1000000) a, range(1000000) b"  # minutes of work


@pytest.fixture(autouse=True)
def state_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The user's state folder (the history's home) and the current folder (exports) in tmp_path."""
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state"))
    monkeypatch.chdir(tmp_path)
    return tmp_path / "state"


async def open_console(app: Any, pilot: Any) -> SqlPane:
    await episodes_ready(app, pilot)
    await pilot.press("5")
    await wait_for(pilot, lambda: app.screen.panes["sql"].is_attached)
    return app.screen.panes["sql"]


def status(sql: SqlPane) -> str:
    return str(sql.query_one("#sql-status").render())


def test_console_opens_idle_and_failed_or_cancelled_queries_leave_no_stale_result() -> None:
    """Before: the empty results said "loading… (Esc cancels)" while nothing ran; an error kept the previous
    result under its message; a second Ctrl+R during a long query waited behind it (minutes)."""
    async def body(app: Any, pilot: Any) -> None:
        sql = await open_console(app, pilot)
        results = sql.query_one(LazyTable)
        text = await shown_once(app, pilot, lambda t: "no query run yet" in t)
        assert "no query run yet" in text and "loading" not in text and not app.screen.source.busy

        await run_query(pilot, sql, "SELECT 41 AS answer")
        await wait_for(pilot, lambda: loaded(results) and results.count == 1)
        await run_query(pilot, sql, "SELECT answer FORM nowhere")
        await wait_for(pilot, lambda: sql.last_error is not None)
        assert results.source is None and results.count == 0 and sql.result is None
        text = await shown_once(app, pilot, lambda t: "the query failed" in t)
        assert "syntax error" in text and "the query failed" in text and " 41" not in text

        try:
            await run_query(pilot, sql, ENDLESS)
            await wait_for(pilot, lambda: app.screen.source.busy and sql._executing is not None)
            assert "running query" in status(sql)
            await run_query(pilot, sql, "SELECT 42 AS answer")   # while the endless one runs
            await wait_for(pilot, lambda: loaded(results) and results.count == 1)
        finally:
            app.screen.source.con.interrupt()   # on a regression the endless query must not outlive the test
        assert results.row(0)["answer"] == 42 and sql.last_error is None
        assert "INTERRUPT" not in await shown(app, pilot) and "error" not in status(sql)
    run_app([ADVANCED], body, size=(100, 30))


def test_closing_a_run_cancels_its_running_query() -> None:
    """Before: closing the run (leaving the app) waited for the running query to end, minutes here."""
    source = RunSource(ADVANCED)
    query = threading.Thread(target=lambda: _swallow(lambda: source.arrow(ENDLESS)), daemon=True)
    query.start()
    while not source.busy:
        query.join(0.01)
    closing = threading.Thread(target=source.close, daemon=True)
    closing.start()
    closing.join(timeout=PATIENCE)
    if closing.is_alive():   # a regression: stop the query so the test process can end
        source.con.interrupt()
    assert not closing.is_alive()


def _swallow(fn: Any) -> None:
    try:
        fn()
    except Exception:  # noqa: BLE001 - the interrupted query's error is expected
        pass


def test_saved_query_parameters_have_labels_and_history_outlives_the_app(state_home: Path) -> None:
    """Before: hid_behind_mountain's five boxes showed only values; the history was gone with the app."""
    history_file = state_home / "tracelab" / "sql_history"

    async def first(app: Any, pilot: Any) -> None:
        sql = await open_console(app, pilot)
        await pilot.press("f2")
        await wait_for(pilot, lambda: type(app.screen).__name__ == "SavedQueryPicker")
        picker = app.screen
        picker.query_one("OptionList").highlighted = [q.name for q in picker.queries].index("hid_behind_mountain")
        await pilot.press("enter")
        await wait_for(pilot, lambda: len(picker.query("Input")) == 5)
        text = await shown(app, pilot)
        for name, default in (("learner", "red-agent-%"), ("enemy", "blue-agent-%"), ("loc_label", "atLoc"),
                              ("mountain_label", "mountain"), ("width", "8")):
            label = str(picker.query_one(f"#label-{name}").render())
            assert label.startswith(name) and f"default {default}" in label
            assert name in text
        assert "grid width" in text and "the location label" in text   # each box's description
        await pilot.press("escape")
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen")
        for statement in ("SELECT 1 AS one", "SELECT count(*) AS n\nFROM episodes"):
            await run_query(pilot, sql, statement)
            await wait_for(pilot, lambda: sql.result is not None and sql.result.column_names[0] in statement)
    run_app([ADVANCED], first, size=(100, 30))

    assert stat.S_IMODE(history_file.stat().st_mode) == 0o600
    assert load_history(history_file) == ["SELECT 1 AS one", "SELECT count(*) AS n\nFROM episodes"]

    async def second(app: Any, pilot: Any) -> None:   # a new app: F3 lists the last session's queries
        sql = await open_console(app, pilot)
        await pilot.press("f3")
        await wait_for(pilot, lambda: type(app.screen).__name__ == "HistoryPicker")
        await pilot.press("enter")                      # the newest first
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen")
        assert sql.editor.text == "SELECT count(*) AS n\nFROM episodes"
    run_app([ADVANCED], second, size=(100, 30))


def test_history_file_is_capped_and_a_bad_one_is_ignored_never_followed(state_home: Path) -> None:
    history_file = state_home / "tracelab" / "sql_history"
    history_file.parent.mkdir(parents=True)
    history_file.write_text(json.dumps([f"SELECT {i}" for i in range(HISTORY_CAP + 100)]))
    assert load_history(history_file) == [f"SELECT {i}" for i in range(100, HISTORY_CAP + 100)]
    for bad in ("{not json", json.dumps({"a": 1}), json.dumps([1, 2]), "\xff\xfe"):
        history_file.write_text(bad, encoding="latin-1")
        assert load_history(history_file) == []
    elsewhere = state_home / "elsewhere.json"
    elsewhere.write_text(json.dumps(["SELECT 'secret'"]))
    history_file.unlink()
    history_file.symlink_to(elsewhere)
    assert load_history(history_file) == []            # not read through the link

    async def body(app: Any, pilot: Any) -> None:
        sql = await open_console(app, pilot)
        assert sql.history == []
        await run_query(pilot, sql, "SELECT 7 AS seven")
        await wait_for(pilot, lambda: sql.result is not None)
        assert sql.history == ["SELECT 7 AS seven"]     # kept for the session
    run_app([ADVANCED], body, size=(100, 30))
    assert json.loads(elsewhere.read_text()) == ["SELECT 'secret'"]   # nor written through it
    assert history_file.is_symlink()


def test_f4_exports_the_result_to_csv_and_parquet_and_asks_before_replacing(tmp_path: Path) -> None:
    """Before: there was no way to save a result but copying the screen."""
    async def export(app: Any, pilot: Any, path: str | None) -> Any:
        await pilot.press("f4")
        await wait_for(pilot, lambda: type(app.screen).__name__ == "ExportDialog")
        dialog = app.screen
        if path is not None:
            dialog.query_one("Input").value = path
        await pilot.press("enter")
        return dialog

    async def body(app: Any, pilot: Any) -> None:
        sql = await open_console(app, pilot)
        await pilot.press("f4")                                       # nothing to export yet: says so
        await wait_for(pilot, lambda: any("run a query first" in str(n.message) for n in app._notifications))
        await run_query(pilot, sql, "SELECT episode, outcome, steps FROM episodes ORDER BY episode")
        await wait_for(pilot, lambda: sql.result is not None)
        expected = sql.result

        await export(app, pilot, None)                                # the default: a new name here
        csv_file = tmp_path / "advanced-sql.csv"
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen" and csv_file.exists())
        assert pacsv.read_csv(csv_file).to_pylist() == expected.to_pylist()

        dialog = await export(app, pilot, None)                       # the default never replaces it
        await wait_for(pilot, lambda: (tmp_path / "advanced-sql-2.csv").exists())
        assert dialog.default.name == "advanced-sql-2.csv"

        await export(app, pilot, "result.parquet")
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen" and Path("result.parquet").exists())
        assert pq.read_table(tmp_path / "result.parquet").equals(expected)

        csv_file.write_text("mine\n")
        dialog = await export(app, pilot, str(csv_file))              # exists: it says so, writes nothing
        message = dialog.query_one("#export-message")
        await wait_for(pilot, lambda: "exists" in str(message.render()))
        assert csv_file.read_text() == "mine\n" and type(app.screen).__name__ == "ExportDialog"
        await pilot.press("enter")                                    # Enter again: replaced
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen")
        assert pacsv.read_csv(csv_file).to_pylist() == expected.to_pylist()

        dialog = await export(app, pilot, "result.xlsx")              # an unknown format: one line, stays
        await wait_for(pilot, lambda: ".csv or .parquet" in str(dialog.query_one("#export-message").render()))
        assert not Path("result.xlsx").exists()
        await pilot.press("escape")
    run_app([ADVANCED], body, size=(100, 30))
