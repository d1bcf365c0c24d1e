"""The TUI keeps your place (issue 27 part 7): Esc steps back one view, a reopened run opens where it was
left, quick `]` presses keep the timestep, the Episodes' outcome selector has a key, and 80x24 with the
board shown keeps the rule column readable and the cursor row on screen; Esc cancels the query the user
waits on, never background work. Headless, on the sample runs."""
from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any


os.environ["TEXTUAL_ANIMATIONS"] = "none"

from tracelab.store.reader import open_run, query_readonly  # noqa: E402
from tracelab.viewers.tui.lazy_table import LazyTable  # noqa: E402
from tracelab.viewers.tui.source import background  # noqa: E402
from tracelab.viewers.tui.trace import TracePane  # noqa: E402
from tui_helpers import back, episodes_ready, has_rows, loaded, run_app, shown, wait_for  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
ADVANCED = ROOT / "sample_runs" / "advanced"
BASE_TRAIN = ROOT / "sample_runs" / "base-train"
ENDLESS = "SELECT sum(a.range * b.range) FROM range(1000000) a, range(1000000) b"  # minutes of work


def active_view(app: Any) -> str:
    return app.screen.query_one("TabbedContent").active


async def open_trace(app: Any, pilot: Any) -> tuple[TracePane, LazyTable]:
    await episodes_ready(app, pilot)
    await pilot.press("enter")
    pane = app.screen.query_one(TracePane)
    await wait_for(pilot, lambda: pane.filter is not None and has_rows(pane.table))
    await wait_for(pilot, lambda: app.focused is pane.table)
    return pane, pane.table


def test_esc_steps_back_one_view_why_trace_episodes_then_runs() -> None:
    async def body(app: Any, pilot: Any) -> None:
        pane, trace = await open_trace(app, pilot)
        await pilot.press("w")
        await wait_for(pilot, lambda: active_view(app) == "why")
        await back(app, pilot)                                    # why -> the trace it explained
        await wait_for(pilot, lambda: active_view(app) == "trace" and app.focused is trace)
        await back(app, pilot)                                    # trace -> the run's episodes
        await wait_for(pilot, lambda: active_view(app) == "episodes")
        assert type(app.screen).__name__ == "RunScreen"
        await pilot.press("4")
        rules = app.screen.query_one("#rules-table", LazyTable)
        await wait_for(pilot, lambda: active_view(app) == "rules" and loaded(rules))
        await back(app, pilot)                                    # any other view -> episodes
        await wait_for(pilot, lambda: active_view(app) == "episodes")
        await wait_for(pilot, lambda: app.focused is app.screen.query_one("#ep-table"))
        await back(app, pilot)                                    # episodes -> the Runs list
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunsScreen")
    run_app([ADVANCED], body)


def cancelled_notes(app: Any) -> list[str]:
    return [str(n.message) for n in app._notifications if "cancelled" in str(n.message)]


def test_esc_goes_back_past_background_work_and_closing_the_run_stops_it() -> None:
    """Before: Esc cancelled whatever query ran, background work the user never asked for too (the
    trace's warm-up, the board read for Enter, the Rules view's never-fired count): "query cancelled", and
    the user stayed where they were. Here a minutes-long query of background work holds the connection."""
    started, ended = threading.Event(), threading.Event()

    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("4")
        rules = app.screen.query_one("#rules-table", LazyTable)
        await wait_for(pilot, lambda: active_view(app) == "rules" and loaded(rules))
        source = app.screen.source

        def endless() -> None:
            try:
                source.call(lambda con: (started.set(), query_readonly(con, ENDLESS).fetchall()))
            except Exception:  # noqa: BLE001 - interrupted when the run closes
                pass
            ended.set()

        app.screen.run_worker(background(endless), thread=True, exit_on_error=False)
        await wait_for(pilot, started.is_set)                   # it holds the connection
        await pilot.press("escape")                               # rules -> episodes, at once
        await wait_for(pilot, lambda: active_view(app) == "episodes" or cancelled_notes(app))
        assert active_view(app) == "episodes" and not cancelled_notes(app)
        assert source.busy and not ended.is_set()                 # still at work
        await pilot.press("escape")                               # closing the run stops it
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunsScreen" and ended.is_set())
        assert not cancelled_notes(app)
    run_app([ADVANCED], body)


def test_esc_cancels_the_query_the_user_waits_on_and_stays() -> None:
    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("5")
        sql = app.screen.panes["sql"]
        await wait_for(pilot, lambda: sql.is_attached and app.focused is sql.editor)
        sql.editor.text = ENDLESS
        await pilot.press("ctrl+r")
        await wait_for(pilot, lambda: app.screen.source.foreground_busy and sql._executing is not None)
        await pilot.press("escape")
        await wait_for(pilot, lambda: "cancelled" in str(sql.query_one("#sql-status").render()))
        assert active_view(app) == "sql" and cancelled_notes(app) == ["query cancelled"]
    run_app([ADVANCED], body, size=(100, 30))


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
        await wait_for(pilot, lambda: pane.filter.episode == evals[0] and has_rows(trace))
        await wait_for(pilot, lambda: app.focused is trace)
        jumps = pane.jumps
        pane.query_one("#tr-goto").value = "20"
        await pilot.press("g", "enter")
        await wait_for(pilot, lambda: pane.jumps > jumps and loaded(trace) and trace.cursor_row["t"] == 20)
        for _ in range(3):             # as fast as keys come: before the next game has loaded
            pane.action_eval_game(1)
        await wait_for(pilot, lambda: pane.filter.episode == evals[3] and has_rows(trace))
        await pilot.pause(0.3)
        assert pane.filter.episode == evals[3]
        assert trace.cursor_row["t"] == 20 and trace.row(trace.cursor - 1)["t"] < 20
    run_app([BASE_TRAIN], body, size=(120, 34))


def test_o_steps_the_episodes_outcome_selector_and_the_key_bar_says_so() -> None:
    async def body(app: Any, pilot: Any) -> None:
        table = await episodes_ready(app, pilot)
        assert " o outcome " in (await shown(app, pilot)).splitlines()[-1]     # the key bar, at 80 columns
        select = app.screen.query_one("#ep-outcome")
        con = open_run(ADVANCED)
        outcomes = [o for (o,) in con.execute("SELECT outcome FROM episodes").fetchall()]
        con.close()
        seen = []
        for _ in range(3):                                          # all -> each outcome the run has -> all
            await pilot.press("o")
            await wait_for(pilot, lambda: loaded(table) and table.count == (
                len(outcomes) if select.is_blank() else outcomes.count(select.value)))
            seen.append(None if select.is_blank() else select.value)
            assert {table.row(i)["outcome"] for i in range(table.count)} == (
                set(outcomes) if select.is_blank() else {select.value} & set(outcomes))
        assert {x for x in seen if x} == set(outcomes) and None in seen   # advanced's games: all losses
    run_app([ADVANCED], body)


def test_a_run_reopened_in_the_session_opens_where_it_was_left() -> None:
    """Episodes filtered and sorted with the cursor on a row, a trace filtered with the cursor on a change:
    Esc to the Runs screen and Enter on the run again opens the trace there, and Episodes as left."""
    async def body(app: Any, pilot: Any) -> None:
        runs = app.screen.query_one(LazyTable)
        await wait_for(pilot, lambda: loaded(runs) and runs.count == 5)
        runs.move_to([runs.row(i)["name"] for i in range(runs.count)].index("advanced"))
        await pilot.press("enter")
        table = await episodes_ready(app, pilot)
        episodes = app.screen.query_one("EpisodesPane")
        app.screen.query_one("#ep-outcome").value = "loss"
        await pilot.press("s", "s")                                 # losses (all 3: red plays at random), by return
        await wait_for(pilot, lambda: loaded(table) and table.count == 3 and episodes.sort_key == "reward")
        await pilot.press("down")
        await wait_for(pilot, lambda: table.cursor == 1)
        chosen = table.cursor_row["episode"]
        await pilot.press("enter")
        pane = app.screen.query_one(TracePane)
        trace = pane.table
        await wait_for(pilot, lambda: pane.filter is not None and pane.filter.episode == chosen and loaded(trace))
        pane.query_one("#tr-label").value = "atLoc"
        await pilot.press("slash", "enter")
        await wait_for(pilot, lambda: pane.filter.label == "atLoc" and loaded(trace) and app.focused is trace)
        await pilot.press("down", "down", "down", "s")              # static facts shown, cursor kept
        await wait_for(pilot, lambda: not pane.hide_static and loaded(trace) and trace.cursor > 0)
        left = trace.cursor_row
        await back(app, pilot)                                      # trace -> episodes
        await wait_for(pilot, lambda: active_view(app) == "episodes")
        await back(app, pilot)                                      # -> Runs
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunsScreen")
        await pilot.press("enter")                                  # the same run again: its Episodes as left
        table = await episodes_ready(app, pilot)
        episodes = app.screen.query_one("EpisodesPane")
        assert active_view(app) == "episodes"
        await wait_for(pilot, lambda: loaded(table) and table.count == 3)  # the kept filter's reload, late when loaded
        await pilot.pause(0.3)                                      # no late reload puts the cursor on row 1
        assert app.screen.query_one("#ep-outcome").value == "loss" and episodes.sort_key == "reward"
        assert table.count == 3 and table.cursor == 1 and table.cursor_row["episode"] == chosen
        await pilot.press("2")                                      # and its trace as left
        pane = app.screen.query_one(TracePane)
        trace = pane.table
        await wait_for(pilot, lambda: active_view(app) == "trace" and pane.filter is not None and loaded(trace))
        assert pane.filter.episode == chosen and pane.filter.label == "atLoc" and not pane.hide_static
        assert trace.error is None and trace.count > 0, (trace.error, trace.count, pane.filter)
        assert trace.cursor_row["seq"] == left["seq"] and trace.cursor == 3
        assert pane.query_one("#tr-label").value == "atLoc"
    run_app([ROOT / "sample_runs"], body, size=(100, 30))


def test_at_80x24_beside_the_board_every_trace_column_fits_and_the_cursor_row_shows() -> None:
    """80x24 is the floor: with the board shown (b) the trace's columns narrow to fit beside it (the rule
    column 12 wide, not two characters behind a sideways scroll), and the cursor row stays on screen."""
    async def body(app: Any, pilot: Any) -> None:
        pane, trace = await open_trace(app, pilot)
        assert not pane.side_box.display                         # no room beside the table: hidden
        await pilot.press("end")
        await wait_for(pilot, lambda: loaded(trace) and trace.cursor == trace.count - 1)
        await pilot.press("b")
        await wait_for(pilot, lambda: pane.side_box.display and pane.board.board is not None)
        await pilot.pause(0.3)
        widths = {c.key: c.width for c in trace.columns}
        assert widths["rule"] >= 12 and widths["node"] >= 12
        assert trace._total_width() <= trace.scrollable_content_region.width      # no sideways scroll
        assert trace.scrollable_content_region.height == trace.size.height        # so no scrollbar row
        for keys in ((), ("pageup", "pageup", "up"), ("home", "pagedown", "down")):
            for key in keys:
                await pilot.press(key)
            await wait_for(pilot, lambda: loaded(trace))
            row = trace.cursor_row
            lines = (await shown(app, pilot)).splitlines()
            at = [ln for ln in lines if ln.lstrip().startswith(f"{row['t']} ") and row["rule"][:11] in ln
                  and row["label"][:6] in ln]
            assert at, (row, "\n".join(lines))                   # the cursor's row, its rule readable
    run_app([ADVANCED], body, size=(80, 24))


def test_the_key_bar_draws_every_key_whole_at_120_columns_and_drops_whole_keys_help_last_at_80() -> None:
    """The key bar of a play run's Trace: at 120 columns every key fits (it read `q qui` on the spec
    runs); at 80 the keys that do not fit are dropped whole from the end of the list, `? help` kept."""
    def expect(app: Any) -> list[tuple[str, str]]:
        out, seen = [], set()
        for _, binding, enabled, _ in app.screen.active_bindings.values():
            if binding.show and enabled and binding.action not in seen:
                seen.add(binding.action)
                out.append((binding.action, f" {app.get_key_display(binding)} {binding.description}"))
        return out

    for size in ((120, 40), (80, 24)):
        async def body(app: Any, pilot: Any, size: tuple[int, int] = size) -> None:
            await open_trace(app, pilot)
            keys = expect(app)
            bar = (await shown(app, pilot)).splitlines()[-1]
            assert bar.rstrip().endswith("^p palette")
            drawn = [action for action, text in keys if text + " " in bar + " "]
            assert "help" in drawn, bar
            rest = bar.replace("^p palette", "")
            for action, text in keys:
                if action in drawn:
                    rest = rest.replace(text, "", 1)
            assert not rest.strip(), (rest, bar)                     # nothing cut: only whole keys drawn
            if size[0] == 120:
                assert drawn == [a for a, _ in keys], bar            # every key
            else:                                                    # dropped from the end, help kept
                kept = [a for a, _ in keys if a != "help"][:len(drawn) - 1]
                assert drawn == [a for a, _ in keys if a in kept or a == "help"], bar
        run_app([ADVANCED], body, size=size)


def test_a_spec_run_and_an_older_rulesim_run_draw_their_board_the_same_way() -> None:
    """One board path: a spec run (its config's [board]) and a run RuleSim wrote (board_state reads
    war.toml for it) both show the board beside the trace, the decision panel under it, and no atoms
    panel (a spec run had the board inside the boardless runs' atoms and graph side)."""
    from tracelab.viewers.tui.board import BoardView, draw
    from tracelab.viewers.tui.decision import DecisionPanel
    from tracelab.viewers.tui.graph_side import GraphSide

    for run in (ADVANCED, ROOT / "tests" / "data" / "rulesim" / "base"):
        async def body(app: Any, pilot: Any) -> None:
            pane, _ = await open_trace(app, pilot)
            assert not app.screen.query(GraphSide)
            board = pane.side
            assert isinstance(board, BoardView) and board.parent is pane.query_one("#tr-side")
            assert pane.query_one("#tr-side").query(DecisionPanel)
            await wait_for(pilot, lambda: board.board is not None)
            drawn = draw(board.declared, board.board.at(board.step)).plain
            assert "R1" in drawn and "B1" in drawn, drawn
        run_app([run], body, size=(120, 34))
