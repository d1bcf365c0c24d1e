"""The terminal UI, headless (textual's run_test + Pilot), on the real sample runs and on a live run written
by another process, checked through the rendered text (the SVG screenshot's text) and the widgets' state.
Golden-file snapshots of the main screens: test_tui_snapshots.py."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from tracelab.cli import main as cli_main  # noqa: E402
from tracelab.store.catalog import list_runs  # noqa: E402
from tracelab.store.reader import open_run  # noqa: E402
from tracelab.viewers.tui.episode_index import cached_index, episode_index  # noqa: E402
from tracelab.viewers.tui.lazy_table import LazyTable  # noqa: E402
from tracelab.viewers.tui.paging import PAGE  # noqa: E402
from tracelab.viewers.tui.trace_paging import TraceFilter, TraceSource  # noqa: E402
from tracelab.viewers.tui.plot import BraillePlot  # noqa: E402
from tracelab.viewers.tui.source import RunSource  # noqa: E402
from tracelab.viewers.tui.sql import SqlPane, locate_error  # noqa: E402
from tracelab.viewers.tui.trace import TracePane, parse_range  # noqa: E402
from tracelab.viewers.tui.why import WhyPane  # noqa: E402
from tui_helpers import (  # noqa: E402
    episodes_ready,
    has_rows,
    live_run,
    loaded,
    pick_saved_query,
    run_app,
    shown,
    shown_once,
    wait_for,
)

ROOT = Path(__file__).resolve().parent.parent
ADVANCED = ROOT / "sample_runs" / "advanced"


async def open_first_trace(app: Any, pilot: Any) -> tuple[TracePane, LazyTable]:
    """From the Episodes view, Enter on the first episode; its trace's first page on screen."""
    await episodes_ready(app, pilot)
    await pilot.press("enter")
    pane = app.screen.query_one(TracePane)
    await wait_for(pilot, lambda: has_rows(pane.table))
    return pane, pane.table


# ---- the catalog and `tracelab runs` ---------------------------------------------------------------------

def test_catalog_lists_the_sample_runs_with_counts(capsys: pytest.CaptureFixture[str]) -> None:
    runs = {r.name: r for r in list_runs([ROOT / "sample_runs"])}
    assert set(runs) == {"base", "advanced", "nonmarkov", "base-train", "supply-chain"}
    adv = runs["advanced"]
    con = open_run(ADVANCED)
    assert adv.rows == con.execute("SELECT count(*) FROM changes").fetchall()[0][0] > 0
    assert adv.episodes == con.execute("SELECT count(*) FROM episodes").fetchall()[0][0]
    assert adv.status == "finished" and adv.scenario == "advanced" and adv.size > 0
    assert cli_main(["runs", str(ROOT / "sample_runs")]) == 0
    out = capsys.readouterr().out
    assert "advanced" in out and "finished" in out and f"{adv.rows}" in out
    assert cli_main(["runs", str(ROOT / "no-such-dir")]) == 1
    assert "no such directory" in capsys.readouterr().err


# ---- paging ------------------------------------------------------------------------------------------------

def plain_seqs(source: RunSource, flt: TraceFilter) -> list[int]:
    """The seqs of the rows `flt` keeps, by a plain query over the changes view (no paging, no index)."""
    return [r["seq"] for r in source.rows(
        "SELECT seq FROM changes WHERE episode = $e AND ($lo IS NULL OR t >= $lo) AND ($hi IS NULL OR t <= $hi) "
        "AND atom GLOB $a AND label GLOB $l AND rule GLOB $r AND ($id IS NULL OR atom_id = $id) ORDER BY seq",
        {"e": flt.episode, "lo": flt.t_from, "hi": flt.t_to, "a": flt.atom or "*", "l": flt.label or "*",
         "r": flt.rule or "*", "id": flt.atom_id})]


@pytest.mark.parametrize("flt", [TraceFilter(0), TraceFilter(0, rule="snap_*"), TraceFilter(1, label="atLoc"),
                                 TraceFilter(2, t_from=3, t_to=9, atom="*red-agent-1*")])
def test_trace_pages_match_the_changes_view_in_every_order_of_access(flt: TraceFilter) -> None:
    source = RunSource(ADVANCED)
    expected = plain_seqs(source, flt)
    assert expected
    by_hints = TraceSource(source, flt)       # pages found from hints, last page first
    assert by_hints.prepare() == len(expected)
    pages = (len(expected) + PAGE - 1) // PAGE
    got = {p: [r["seq"] for r in by_hints.fetch(p)] for p in reversed(range(pages))}
    assert by_hints.anchors is None or pages > 2
    by_anchors = TraceSource(source, flt)
    by_anchors.prepare()
    by_anchors.warm()
    for p in range(pages):
        assert got[p] == expected[p * PAGE:(p + 1) * PAGE] == [r["seq"] for r in by_anchors.fetch(p)]
    spanned = TraceSource(source, flt)         # all pages in one range query from the hint at row 0
    spanned.prepare()
    assert [r["seq"] for _, rows in spanned.fetch_pages(0, pages - 1) for r in rows] == expected
    middle = len(expected) // 2
    opener = TraceSource(source, flt, ("seq", expected[middle]))  # opens on a given change
    opener.prepare()
    assert opener.start_row == middle
    assert opener.fetch(middle // PAGE)[middle % PAGE]["seq"] == expected[middle]
    jumper = TraceSource(source, flt)
    jumper.prepare()
    t = by_anchors.fetch(pages - 1)[-1]["t"]
    row = jumper.row_of_t(t)
    assert jumper.fetch(row // PAGE)[row % PAGE]["t"] == t and (row == 0 or expected[row - 1] < expected[row])


@pytest.mark.parametrize("flt", [
    TraceFilter(0), TraceFilter(0, rule="action"), TraceFilter(1, rule="fact:*"), TraceFilter(0, rule="snap_*"),
    TraceFilter(1, label="atLoc", rule="action"), TraceFilter(2, atom="*red-agent-1*"),
    TraceFilter(2, t_from=3, t_to=9), TraceFilter(0, t_from=5, label="alive"),
    TraceFilter(1, atom_id=0, t_to=40), TraceFilter(0, rule="no-such-rule")])
def test_filters_answered_from_the_episode_index_equal_plain_sql(flt: TraceFilter) -> None:
    """Counts, pages, start rows and jumps through the in-memory episode index are those of the SQL path
    and of a plain query over the changes view."""
    source = RunSource(ADVANCED)
    expected = plain_seqs(source, flt)
    if flt.atom_id is not None:           # atom 0 changes in that episode: the filter keeps something
        assert expected
    by_sql = TraceSource(source, flt)
    assert by_sql.prepare() == len(expected) and cached_index(source, flt.episode) is None
    assert episode_index(source, flt.episode) is not None
    indexed = TraceSource(source, flt)
    assert indexed.prepare() == len(expected)
    assert indexed.anchors is not None     # answered from the index: no warm-up needed
    pages = (len(expected) + PAGE - 1) // PAGE
    assert [r["seq"] for p in range(pages) for r in indexed.fetch(p)] == expected
    for i in sorted({0, len(expected) // 3, len(expected) - 1} if expected else set()):
        for start in (("seq", expected[i]), ("seq", expected[i] - 1), ("t", by_sql.fetch(i // PAGE)[i % PAGE]["t"])):
            opened = TraceSource(source, flt, start)
            assert opened.prepare() == len(expected) and opened.anchors is not None
            row = _sql_start_row(flt, start)
            assert opened.start_row == row
            assert opened.fetch(row // PAGE)[row % PAGE]["seq"] == expected[row]
        t = by_sql.fetch(i // PAGE)[i % PAGE]["t"]
        assert indexed.row_of_t(t) == by_sql.row_of_t(t)
        assert indexed.row_of_seq(expected[i]) == by_sql.row_of_seq(expected[i]) == i
        atom = int(by_sql.fetch(i // PAGE)[i % PAGE]["atom_id"])
        for forward in (True, False):
            assert indexed.next_change(atom, expected[i], forward) == by_sql.next_change(atom, expected[i], forward)


def _sql_start_row(flt: TraceFilter, start: tuple[str, int]) -> int:
    """Where a TraceSource opening at `start` puts the cursor, by SQL alone (a fresh run, no index)."""
    fresh = TraceSource(RunSource(ADVANCED), flt, start)
    fresh.prepare()
    return fresh.start_row


def test_time_ranges_and_error_positions_are_read() -> None:
    assert parse_range("3..9") == (3, 9) and parse_range("..9") == (None, 9) and parse_range("5") == (5, 5)
    assert parse_range("") == (None, None)
    with pytest.raises(ValueError):
        parse_range("x..")
    err = locate_error("SELECT *\nFORM changes", 'Parser Error: syntax error at or near "FORM"\n\n'
                                                 "LINE 2: FORM changes\n        ^")
    assert (err.line, err.column) == (1, 0) and "syntax error" in err.message


# ---- the app -------------------------------------------------------------------------------------------------

def test_open_a_run_go_to_an_episode_filter_by_rule_and_explain_a_death() -> None:
    async def body(app: Any, pilot: Any) -> None:
        episodes = await episodes_ready(app, pilot)
        text = await shown_once(app, pilot, lambda t: "loss" in t)  # rows drawn after loading
        assert "1 Episodes" in text and "loss" in text
        assert episodes.count == 3 and episodes.cursor_row["episode"] == 0
        episodes.move_to(2)                                         # red-agent-1 is shot dead in episode 2
        await wait_for(pilot, lambda: episodes.cursor_row is not None and episodes.cursor_row["episode"] == 2)
        await pilot.press("enter")                                  # episode 2's trace
        trace = app.screen.query_one("#tr-table", LazyTable)
        await wait_for(pilot, lambda: has_rows(trace))
        all_rows = trace.count
        pane = app.screen.query_one(TracePane)
        pane.query_one("#tr-rule").value = "d_killed"
        await pilot.press("slash", "enter")                         # apply the filters
        await wait_for(pilot, lambda: pane.filter.rule == "d_killed" and loaded(trace))
        assert 0 < trace.count < all_rows
        assert {trace.row(i)["rule"] for i in range(trace.count)} == {"d_killed"}
        death = next(i for i in range(trace.count) if trace.row(i)["atom"] == "alive(red-agent-1)")
        assert trace.row(death)["t"] == 14 and trace.row(death)["new_upper"] == 0
        trace.move_to(death)
        await pilot.pause()
        assert "d_killed" in await shown(app, pilot) and "alive(red-agent-1)" in await shown(app, pilot)
        await pilot.press("w")                                      # why
        why = app.screen.query_one(WhyPane)
        tree = why.query_one("Tree")
        await wait_for(pilot, lambda: tree.root.data is not None)
        root = tree.root.data
        assert root.atom == "alive(red-agent-1)" and root.value == [0, 0] and root.cause.name == "d_killed"
        assert str(tree.root.label).startswith("alive(red-agent-1) = [1,1] → [0,0]  t=14 by d_killed")
        children = [str(c.label) for c in tree.root.children]
        assert any("killed(red-agent-1)" in c and c.startswith("ok") for c in children)
        assert "killed(red-agent-1)" in await shown(app, pilot)
        killed = tree.root.children[0]
        assert killed.data.cause.name == "h_killed" and killed.children      # expandable, one level deeper
        await pilot.press("4")                                      # from the tree to another view
        await wait_for(pilot, lambda: app.screen.query_one("TabbedContent").active == "rules")
        await pilot.pause(0.3)
        assert app.screen.query_one("TabbedContent").active == "rules"
    run_app([ADVANCED], body)


def test_next_and_previous_change_of_the_selected_atom_and_jump_to_a_step() -> None:
    async def body(app: Any, pilot: Any) -> None:
        pane, trace = await open_first_trace(app, pilot)
        jumps = pane.jumps
        pane.query_one("#tr-goto").value = "7"
        await pilot.press("g", "enter")
        await wait_for(pilot, lambda: pane.jumps > jumps and loaded(trace))
        first7 = trace.cursor
        assert trace.cursor_row["t"] == 7 and trace.row(first7 - 1)["t"] < 7
        atom, seq = trace.cursor_row["atom"], trace.cursor_row["seq"]
        await pilot.press("n")
        await wait_for(pilot, lambda: pane.jumps > jumps + 1 and loaded(trace))
        nxt = trace.cursor_row
        if nxt["seq"] != seq:                                        # the atom changed again later
            assert nxt["atom"] == atom and nxt["seq"] > seq
            assert all(trace.row(i)["atom"] != atom for i in range(first7 + 1, trace.cursor))
            await pilot.press("p")
            await wait_for(pilot, lambda: pane.jumps > jumps + 2 and loaded(trace))
            assert trace.cursor_row["seq"] == seq
    run_app([ADVANCED], body, size=(100, 30))


def test_episodes_sort_and_filter_by_outcome_and_length() -> None:
    async def body(app: Any, pilot: Any) -> None:
        table = await episodes_ready(app, pilot)
        pane = app.screen.query_one("EpisodesPane")
        pane.sort_key, pane.sort_desc = "steps", True
        pane.reload()
        await wait_for(pilot, lambda: loaded(table) and table.sort_key == "steps")
        lengths = [table.row(i)["steps"] for i in range(table.count)]
        assert lengths == sorted(lengths, reverse=True) and lengths[0] == 48
        assert "length▼" in await shown(app, pilot)
        app.screen.query_one("#ep-outcome").value = "loss"
        await wait_for(pilot, lambda: loaded(table) and table.count == 3)
        app.screen.query_one("#ep-length").value = "..20"
        pane.reload()
        await wait_for(pilot, lambda: loaded(table) and table.count == 1)
        assert table.row(0)["episode"] == 2 and table.row(0)["outcome"] == "loss"
        await pilot.press("f")                                       # into the length field
        await wait_for(pilot, lambda: app.focused is not None and app.focused.id == "ep-length")
        await pilot.press("escape")                                  # out of it, not out of the run
        await wait_for(pilot, lambda: app.focused is table)
        assert type(app.screen).__name__ == "RunScreen"
    run_app([ADVANCED], body)


def test_sql_console_saved_query_inline_error_and_write_refused() -> None:
    before = ADVANCED.joinpath("run.duckdb").read_bytes()

    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("5")
        await wait_for(pilot, lambda: app.screen.panes["sql"].is_attached)
        sql: SqlPane = app.screen.panes["sql"]
        results = sql.query_one(LazyTable)
        await pick_saved_query(app, pilot, "firings_per_episode", "1")   # its parameter: episode 1
        await wait_for(pilot, lambda: has_rows(results))
        assert {results.row(i)["episode"] for i in range(results.count)} == {1}
        assert "firings_per_episode" in await shown(app, pilot)

        sql.editor.text = "SELECT episode,\n  count(*) FORM changes"  # a typo on line 2
        await pilot.press("ctrl+r")
        await wait_for(pilot, lambda: sql.last_error is not None)
        err = sql.last_error
        assert err.line == 1 and "syntax error" in err.message
        assert sql.editor.cursor_location[0] == 1 and sql.editor.selected_text.strip() != ""
        text = await shown(app, pilot)
        assert "syntax error" in text and "line 2" in text

        for statement in ("DELETE FROM raw.changes", "CREATE TABLE x AS SELECT 1",
                          "ATTACH 'x.duckdb' AS x"):
            sql.editor.text = statement
            sql.last_error = None
            await pilot.press("ctrl+r")
            await wait_for(pilot, lambda: sql.last_error is not None)
            assert "only read-only queries" in sql.last_error.message
        assert "only read-only" in await shown(app, pilot)
    run_app([ADVANCED], body, size=(100, 30))
    assert ADVANCED.joinpath("run.duckdb").read_bytes() == before


def test_rules_view_counts_firings_and_lists_rules_that_never_fired() -> None:
    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("4")
        await wait_for(pilot, lambda: app.screen.panes["rules"].is_attached)
        table = app.screen.panes["rules"].query_one(LazyTable)
        await wait_for(pilot, lambda: has_rows(table))
        rows = [table.row(i) for i in range(min(table.count, PAGE))]
        con = open_run(ADVANCED)
        fired = dict(con.execute("SELECT rule, count(*) FROM firings GROUP BY rule").fetchall())
        assert {r["rule"]: r["firings"] for r in rows if r["firings"]} == fired
        assert [r["firings"] for r in rows] == sorted((r["firings"] for r in rows), reverse=True)
        never = [r["rule"] for r in rows if r["firings"] == 0]
        assert never and not set(never) & set(fired)
        await wait_for(pilot, lambda: "never fired" in app.screen.query_one("#rules-status").render().plain)
        await pilot.press("enter")                                  # the top rule filters the trace
        trace = app.screen.query_one("#tr-table", LazyTable)
        await wait_for(pilot, lambda: app.screen.query_one(TracePane).filter is not None and loaded(trace))
        assert trace.count > 0 and trace.cursor_row["rule"] == rows[0]["rule"]
    run_app([ADVANCED], body)


def test_runs_screen_help_and_palette_at_80x24() -> None:
    async def body(app: Any, pilot: Any) -> None:
        table = app.screen.query_one(LazyTable)
        # base, advanced, nonmarkov, base-train, supply-chain
        await wait_for(pilot, lambda: loaded(table) and table.count == 5)
        text = await shown(app, pilot)
        assert "advanced" in text and "finished" in text and "Enter" in text and "palette" in text
        await pilot.press("question_mark")
        await pilot.pause()
        assert "command palette" in await shown(app, pilot)
        await pilot.press("escape")
        table.move_to([table.row(i)["name"] for i in range(table.count)].index("advanced"))
        await pilot.press("enter")
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen")
        commands = [c.title for c in app.get_system_commands(app.screen)]
        assert "Show Trace" in commands and "Saved queries" in commands
    run_app([ROOT / "sample_runs"], body)


def test_training_curve_updates_while_another_process_appends_metrics(tmp_path: Path) -> None:
    with live_run("train", tmp_path) as run:
        async def body(app: Any, pilot: Any) -> None:
            await pilot.press("6")
            await wait_for(pilot, lambda: app.screen.panes["training"].is_attached)
            loss = app.screen.query_one("#plot-loss", BraillePlot)
            win = app.screen.query_one("#plot-win-rate", BraillePlot)
            await wait_for(pilot, lambda: loss.points > 0)
            first, first_text = loss.points, await shown(app, pilot)
            assert "loss" in first_text and "epsilon" in first_text and "live" in first_text
            await wait_for(pilot, lambda: loss.points >= first + 3 and win.points > 0)
            assert await shown(app, pilot) != first_text
            assert [s.name for s in win.series] == ["eval/win_rate"]
            steps = loss.series[0].xs
            assert steps == sorted(steps) and steps[-1] > steps[0]
            await pilot.press("1")
            episodes = app.screen.query_one("#ep-table", LazyTable)
            await wait_for(pilot, lambda: loaded(episodes) and "kind" in [c.key for c in episodes.columns])
            assert episodes.cursor_row["kind"] == "train" and episodes.cursor_row["train_step"] == 100
        run_app([run], body, size=(100, 30))


def test_board_follows_the_trace_cursor() -> None:
    async def body(app: Any, pilot: Any) -> None:
        pane, trace = await open_first_trace(app, pilot)
        board = pane.board
        assert board is not None and pane.side_box.display          # 120 columns: room for it
        jumps = pane.jumps
        pane.query_one("#tr-goto").value = "21"
        await pilot.press("g", "enter")
        await wait_for(pilot, lambda: pane.jumps > jumps and loaded(trace))
        await wait_for(pilot, lambda: board.board is not None and board.step == 21)
        text = await shown(app, pilot)
        assert "board at t=21" in text
        # advanced episode 0: blue-agent-1 reaches red's base c7_7 at t=21 (the board's last row and column)
        state = board.board.at(21)
        blue = next(p for p in state.pieces if p.thing == "blue-agent-1")
        assert (blue.row, blue.col, blue.alive) == (7, 7, True)
        assert "B1 alive" in text and "R1 alive" in text
        await pilot.press("b")                                         # hide it (its box, with the decision)
        assert not pane.side_box.display
    run_app([ADVANCED], body, size=(120, 34))


def test_the_mouse_selects_rows_sorts_by_header_and_opens_on_double_click() -> None:
    async def body(app: Any, pilot: Any) -> None:
        table = app.screen.query_one("#ep-table", LazyTable)
        await wait_for(pilot, lambda: loaded(table))
        await pilot.click(table, offset=(3, 3))                      # line 0 is the header: row 2
        assert table.cursor == 2 and table.cursor_row["episode"] == 2
        x = sum(c.width + 1 for c in table.columns[:3]) + 1            # the "length" header
        await pilot.click(table, offset=(x, 0))
        await wait_for(pilot, lambda: table.sort_key == "steps" and loaded(table))
        assert [table.row(i)["steps"] for i in range(table.count)] == [14, 21, 48]
        await pilot.click(table, offset=(3, 1))                      # the shortest game: episode 2
        await pilot.click(table, offset=(3, 1), times=2)               # double click: the trace
        trace = app.screen.query_one("#tr-table", LazyTable)
        await wait_for(pilot, lambda: app.screen.query_one(TracePane).filter is not None and loaded(trace))
        assert app.screen.query_one(TracePane).filter.episode == 2
        await pilot.click(app.screen.query_one("KeyBar"), offset=(app.size.width - 3, 0))  # ^p palette
        await pilot.pause()
        assert type(app.screen).__name__ == "CommandPalette"
    run_app([ADVANCED], body)


def test_the_trace_of_a_live_episode_grows_and_keeps_its_cursor(tmp_path: Path) -> None:
    with live_run("trace", tmp_path) as run:
        async def body(app: Any, pilot: Any) -> None:
            episodes = app.screen.query_one("#ep-table", LazyTable)
            await wait_for(pilot, lambda: loaded(episodes) and episodes.count == 1 and app.focused is episodes)
            await pilot.press("enter")
            pane = app.screen.query_one(TracePane)
            trace = pane.table
            await wait_for(pilot, lambda: has_rows(trace))
            first = trace.count
            trace.move_to(first - 1)
            await wait_for(pilot, lambda: loaded(trace))
            seq = trace.cursor_row["seq"]
            await wait_for(pilot, lambda: trace.count > first and loaded(trace))
            assert trace.cursor_row["seq"] == seq          # still on the change it was on
            assert trace.row(trace.count - 1) is None or trace.row(trace.count - 1)["seq"] > seq
        run_app([run], body)


def test_why_of_a_change_its_atom_undid_later_in_the_step_is_that_changes_own() -> None:
    """acting(clock) changes twice at t=1 (clr_acting in pass 0, p_act in pass 1): the why tree of each
    row is rooted at that row, its rule and its bound, not at the bound at the end of t=1."""
    async def body(app: Any, pilot: Any) -> None:
        pane, trace = await open_first_trace(app, pilot)
        pane.query_one("#tr-atom").value = "acting(clock)"
        await pilot.press("slash", "enter")
        await wait_for(pilot, lambda: pane.filter.atom == "acting(clock)" and loaded(trace))
        rows = [trace.row(i) for i in range(trace.count)]
        first_at_1 = next(i for i, r in enumerate(rows) if r["t"] == 1)
        first, second = rows[first_at_1], rows[first_at_1 + 1]
        assert second["t"] == 1 and first["rule"] != second["rule"]      # changed twice at t=1
        why: WhyPane = app.screen.panes["why"]
        for index, row in ((first_at_1, first), (first_at_1 + 1, second)):
            if index != first_at_1:
                await pilot.press("2")                                   # back from the why tree
            await wait_for(pilot, lambda: app.focused is trace)
            trace.move_to(index)
            await pilot.pause()
            await pilot.press("w")
            await wait_for(pilot, lambda: why.is_attached and why.query_one("Tree").root.data is not None
                           and why.query_one("Tree").root.data.seq == row["seq"])
            tree = why.query_one("Tree")
            root = tree.root.data
            assert root.cause.name == row["rule"] and root.pass_no == row["pass_no"]
            assert root.value == [row["new_lower"], row["new_upper"]]
            assert root.old == [row["old_lower"], row["old_upper"]]
            new = f"[{row['new_lower']:g},{row['new_upper']:g}]"
            assert str(tree.root.label).startswith(f"acting(clock) = [{row['old_lower']:g},{row['old_upper']:g}] → {new}")
            assert f"by {row['rule']}" in str(tree.root.label)
            assert f"at t=1 pass {row['pass_no']}" in await shown(app, pilot)
    run_app([ADVANCED], body, size=(120, 30))


BASE_TRAIN = ROOT / "sample_runs" / "base-train"


def test_next_and_previous_evaluation_game_from_the_trace_of_a_training_run() -> None:
    """sample_runs/base-train traces 3 evaluation games per evaluation round: `]` / `[` step through them,
    keeping the trace's filters, and the header says which game is shown (round, train step, outcome and
    length as the run's episodes have them)."""
    con = open_run(BASE_TRAIN)
    rows = con.execute("SELECT episode, train_step, outcome, steps FROM episodes WHERE kind = 'eval' "
                       "ORDER BY episode").fetchall()
    evals = [e for e, _, _, _ in rows]
    assert len(evals) >= 4 and rows[0][1] == rows[2][1] < rows[3][1]  # 3 games a round
    first_step, second_step = f"{rows[0][1]:,}", f"{rows[3][1]:,}"
    next_at_20 = con.execute("SELECT min(t) FROM changes WHERE episode = ? AND label = 'atLoc' AND t >= 20",
                             [evals[1]]).fetchall()[0][0]
    # the spec path's trainer records no opponent p with its evaluation games (RuleSim's did: "· opponent p=0.3")
    first_game = f"eval game 1/3 · round 0 · train step {first_step} · {rows[0][2]}, {rows[0][3]} steps"

    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("enter")                                   # episode 0: a training episode,
        pane = app.screen.query_one(TracePane)                       # not traced
        trace = pane.table
        await wait_for(pilot, lambda: pane.filter is not None and loaded(trace) and pane.query_one("#tr-game").display)
        assert trace.count == 0 and "episode 0: a training episode, not an evaluation game" in header_text(pane)
        await pilot.press("right_square_bracket")
        await wait_for(pilot, lambda: pane.filter.episode == evals[0] and has_rows(trace))
        first = trace.cursor_row
        text = await shown(app, pilot)
        assert first_game in text
        assert "]/[ eval games" in text                                # in the key bar
        pane.query_one("#tr-label").value = "atLoc"                    # a filter the next game keeps
        await pilot.press("slash", "enter")
        await wait_for(pilot, lambda: pane.filter.label == "atLoc" and loaded(trace))
        await wait_for(pilot, lambda: app.focused is trace)
        at_20 = next(i for i in range(trace.count) if trace.row(i)["t"] >= 20)
        trace.move_to(at_20)                                           # the cursor at t=20 ...
        await wait_for(pilot, lambda: loaded(trace) and trace.cursor_row["t"] == 20)
        jumps = pane.jumps
        await pilot.press("right_square_bracket")
        await wait_for(pilot, lambda: pane.filter.episode == evals[1] and pane.jumps > jumps and loaded(trace))
        assert pane.filter.label == "atLoc" and trace.count > 0
        # ... stays at t=20: the next game's first atLoc row at or after it (that game may change none at 20)
        assert trace.cursor_row["t"] == next_at_20 and trace.row(trace.cursor - 1)["t"] < 20
        assert {trace.row(i)["label"] for i in range(trace.cursor - 5, trace.cursor + 5)} == {"atLoc"}
        assert f"eval game 2/3 · round 0 · train step {first_step}" in header_text(pane)
        assert len(header_text(pane).split(" · ]/[")[0]) <= 80         # the game fits an 80-column line
        await wait_for(pilot, lambda: pane.board.board is not None and pane.board.board.episode == evals[1])
        await pilot.press("right_square_bracket")
        await wait_for(pilot, lambda: pane.filter.episode == evals[2] and loaded(trace))
        await pilot.press("right_square_bracket")
        await wait_for(pilot, lambda: pane.filter.episode == evals[3] and loaded(trace))
        assert f"eval game 1/3 · round 1 · train step {second_step}" in header_text(pane)
        await pilot.press("left_square_bracket")
        await wait_for(pilot, lambda: pane.filter.episode == evals[2] and loaded(trace))
        assert "eval game 3/3 · round 0" in header_text(pane)
        commands = {c.title: c for c in app.get_system_commands(app.screen)}
        assert "Next evaluation game" in commands
        await pilot.press("1")                                         # the palette's command, from Episodes
        await commands["Previous evaluation game"].callback()
        await wait_for(pilot, lambda: pane.filter.episode == evals[1] and loaded(trace))
        assert app.screen.query_one("TabbedContent").active == "trace"
        assert first is not None and first["t"] == 0
    run_app([BASE_TRAIN], body, size=(120, 34))


def header_text(pane: TracePane) -> str:
    return str(pane.query_one("#tr-game").render())


def test_evaluation_game_keys_are_not_offered_on_a_run_without_evaluation_games() -> None:
    """A play run has no evaluation games: ]/[ is neither in the key bar nor bound (a key that could only
    say no); a training run's trace offers it (test_the_trace_steps_through_evaluation_games...)."""
    async def body(app: Any, pilot: Any) -> None:
        pane, trace = await open_first_trace(app, pilot)
        assert not pane.source.has_eval_games and not pane.source.live
        assert pane.check_action("eval_game", (1,)) is False and pane.check_action("eval_game", (-1,)) is False
        assert "]/[ eval games" not in await shown(app, pilot)
        assert pane.filter.episode == 0 and not pane.query_one("#tr-game").display
    run_app([ADVANCED], body)


def test_a_table_measures_its_own_copy_of_the_column_definitions() -> None:
    """Widths measured on one table's first page never leak into the (module-level) column definitions,
    so a second table, or the same screen in a second app of the process, measures its own rows."""
    from tracelab.viewers.tui.lazy_table import Column
    definitions = [Column("name", "run", None, max_width=24)]
    wide, narrow = LazyTable(definitions), LazyTable(definitions)
    wide._measure([{"name": "a-very-long-run-name"}])
    narrow._measure([{"name": "base"}])
    assert definitions[0].width is None
    assert wide.columns[0].width == len("a-very-long-run-name") and narrow.columns[0].width == len("base")


def test_plot_axis_labels_fit_the_axis() -> None:
    """Every y label fits the axis column (a return of -1,440 was cut to '-1.44e' in the Training view)."""
    from tracelab.viewers.tui.plot import AXIS_W, _fmt
    values = [-1440.0, -14_400.5, 250.0, 0.93, 3.2e-4, -3.1e-3, 2.5e6, -2.5e7, 999.7, -212.3, 1.0, -0.05]
    labels = {v: _fmt(v) for v in values}
    assert all(len(t) <= AXIS_W - 1 for t in labels.values()), labels
    assert labels[-1440.0] == "-1.44k" and labels[250.0] == "250" and labels[-3.1e-3] == "-3e-3"
    assert all(abs(float(t.replace("k", "e3").replace("M", "e6")) - v) <= 0.06 * abs(v) for v, t in labels.items())


def test_only_the_selected_atom_names_the_atom_in_the_status_line() -> None:
    """`a` filters the trace to the atom under the cursor; the status line says which atom, not its id."""
    async def body(app: Any, pilot: Any) -> None:
        pane, trace = await open_first_trace(app, pilot)
        atom = trace.cursor_row["atom"]
        await pilot.press("a")
        await wait_for(pilot, lambda: pane.filter is not None and pane.filter.atom_id is not None and loaded(trace))
        status = str(pane.query_one("#tr-status").render())
        assert f"only {atom}" in status and "atom #" not in status, status
        assert {trace.row(i)["atom"] for i in range(trace.count)} == {atom}
    run_app([ADVANCED], body, size=(100, 30))
