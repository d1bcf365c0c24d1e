"""The TUI keeps your place (issue 27 part 7): Esc steps back one view, a reopened run opens where it was
left, quick `]` presses keep the timestep, the Episodes' outcome selector has a key, and 80x24 with the
board shown keeps the rule column readable and the cursor row on screen. Headless, on the sample runs."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from tracelab.store.reader import open_run  # noqa: E402
from tracelab.viewers.tui.lazy_table import LazyTable  # noqa: E402
from tracelab.viewers.tui.trace import TracePane  # noqa: E402
from tui_helpers import episodes_ready, loaded, run_app, shown, wait_for  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
ADVANCED = ROOT / "sample_runs" / "advanced"
BASE_TRAIN = ROOT / "sample_runs" / "base-train"


def active_view(app: Any) -> str:
    return app.screen.query_one("TabbedContent").active


async def open_trace(app: Any, pilot: Any) -> tuple[TracePane, LazyTable]:
    await episodes_ready(app, pilot)
    await pilot.press("enter")
    pane = app.screen.query_one(TracePane)
    await wait_for(pilot, lambda: pane.filter is not None and pane.table.count > 0 and loaded(pane.table))
    await wait_for(pilot, lambda: app.focused is pane.table)
    return pane, pane.table


def test_esc_steps_back_one_view_why_trace_episodes_then_runs() -> None:
    async def body(app: Any, pilot: Any) -> None:
        pane, trace = await open_trace(app, pilot)
        await pilot.press("w")
        await wait_for(pilot, lambda: active_view(app) == "why")
        await pilot.press("escape")                               # why -> the trace it explained
        await wait_for(pilot, lambda: active_view(app) == "trace" and app.focused is trace)
        await pilot.press("escape")                               # trace -> the run's episodes
        await wait_for(pilot, lambda: active_view(app) == "episodes")
        assert type(app.screen).__name__ == "RunScreen"
        await pilot.press("4", "escape")                          # any other view -> episodes
        await wait_for(pilot, lambda: active_view(app) == "episodes")
        await wait_for(pilot, lambda: app.focused is app.screen.query_one("#ep-table"))
        await pilot.press("escape")                               # episodes -> the Runs list
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunsScreen")
    run_app([ADVANCED], body)


def test_quick_eval_game_presses_keep_the_timestep() -> None:
    """Three `]` pressed before the games load land on the third game at the kept timestep (t=20), not
    at t=0: a press made while the previous game is loading takes the timestep it is opening at."""
    evals = [e for (e,) in open_run(BASE_TRAIN).execute(
        "SELECT episode FROM episodes WHERE kind = 'eval' ORDER BY episode").fetchall()]

    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("enter")
        pane = app.screen.query_one(TracePane)
        trace = pane.table
        await wait_for(pilot, lambda: pane.filter is not None and loaded(trace))
        await pilot.press("right_square_bracket")
        await wait_for(pilot, lambda: pane.filter.episode == evals[0] and trace.count > 0 and loaded(trace))
        await wait_for(pilot, lambda: app.focused is trace)
        jumps = pane.jumps
        pane.query_one("#tr-goto").value = "20"
        await pilot.press("g", "enter")
        await wait_for(pilot, lambda: pane.jumps > jumps and loaded(trace) and trace.cursor_row["t"] == 20)
        for _ in range(3):             # as fast as keys come: before the next game has loaded
            pane.action_eval_game(1)
        await wait_for(pilot, lambda: pane.filter.episode == evals[3] and loaded(trace) and trace.count > 0)
        await pilot.pause(0.3)
        assert pane.filter.episode == evals[3]
        assert trace.cursor_row["t"] == 20 and trace.row(trace.cursor - 1)["t"] < 20
    run_app([BASE_TRAIN], body, size=(120, 34))


def test_o_steps_the_episodes_outcome_selector_and_the_key_bar_says_so() -> None:
    async def body(app: Any, pilot: Any) -> None:
        table = await episodes_ready(app, pilot)
        assert " o outcome " in (await shown(app, pilot)).splitlines()[-1]     # the key bar, at 80 columns
        select = app.screen.query_one("#ep-outcome")
        seen = []
        for _ in range(3):                                          # all -> loss -> win -> all
            await pilot.press("o")
            await wait_for(pilot, lambda: loaded(table) and table.count == (3 if select.is_blank() else
                                                                            1 + (select.value == "loss")))
            seen.append(None if select.is_blank() else select.value)
            assert {table.row(i)["outcome"] for i in range(table.count)} == (
                {"loss", "win"} if select.is_blank() else {select.value})
        assert seen == ["loss", "win", None]
    run_app([ADVANCED], body)
