"""The TUI's SQL console on several runs (issue 30, section 3): `tracelab tui RUN RUN` opens the first run
with the others overlaid in Training, and its SQL console reads them all, every view with a first column
`run`; a saved query runs on each run; Esc cancels a query on them. Headless, through textual's Pilot, on
two sample runs."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from tracelab.store.queries import get_query  # noqa: E402
from tracelab.store.reader import open_run, query_readonly  # noqa: E402
from tracelab.viewers.tui.sql import SqlPane  # noqa: E402
from tui_helpers import pick_saved_query, run_app, run_query, wait_for  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
BASE, ADVANCED = ROOT / "sample_runs" / "base", ROOT / "sample_runs" / "advanced"
ENDLESS = "SELECT sum(a.range * b.range) FROM range(1000000) a, range(1000000) b"


async def open_console(app: Any, pilot: Any) -> SqlPane:
    await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen")
    await app.screen.action_show("sql")
    await wait_for(pilot, lambda: app.screen.panes["sql"].is_attached)
    return app.screen.panes["sql"]


def firings_of(run: Path) -> list[dict[str, Any]]:
    query = get_query("firings_per_episode")
    return query_readonly(open_run(run), query.sql, query.bind({"episode": "0"})).to_arrow_table().to_pylist()


def test_the_console_reads_every_run_given() -> None:
    """Before: the console read the first run only (no `run` column; the overlaid runs were Training's)."""
    async def body(app: Any, pilot: Any) -> None:
        sql = await open_console(app, pilot)
        assert "overlaid in Training and SQL" in str(app.screen.query_one("#title").render())
        assert sql.editor.text.startswith("SELECT run, rule")   # the first query shown is per run
        await run_query(pilot, sql, "SELECT run, count(*) AS n FROM episodes GROUP BY run ORDER BY run")
        await wait_for(pilot, lambda: sql.result is not None)
        assert sql.result.to_pylist() == [{"run": "advanced", "n": 3}, {"run": "base", "n": 3}]

        await pick_saved_query(app, pilot, "firings_per_episode", "0")
        await wait_for(pilot, lambda: sql.result is not None and sql.result.column_names[0] == "run")
        assert sql.result.to_pylist() == [{"run": name, **row} for name, run in (("base", BASE), ("advanced", ADVANCED))
                                          for row in firings_of(run)]

        await run_query(pilot, sql, ENDLESS)
        await wait_for(pilot, lambda: app.screen.sql_source.busy and sql._executing is not None)
        await pilot.press("escape")
        await wait_for(pilot, lambda: "cancelled" in str(sql.query_one("#sql-status").render()))
    run_app([BASE, ADVANCED], body, size=(120, 34))
