"""The TUI on a run without a board (a reasoning run, `tracelab reason --run`): beside the trace, the atoms
true (or changed) at the cursor's time, filterable and bounded, and the selected atom's neighbourhood in
the graph; the episodes, rules, why and SQL views without game words; no Training tab. Checked against
the run's own rows (sample_runs/supply-chain), headless through textual's Pilot, and on a synthetic run of
1M changes for the bound. Snapshots of these screens: test_tui_snapshots.py."""
from __future__ import annotations

import re
import sys
import time
import tracemalloc
from pathlib import Path
from typing import Any

import pytest
from tui_helpers import (back, episodes_ready, has_rows, loaded, open_trace_at, run_app, shown, shown_once, svg_text,
                         wait_for)

from tracelab.store.reader import open_run
from tracelab.viewers.tui.graph_side import GraphSide
from tracelab.viewers.tui.graph_state import atoms_at, neighbourhood, unknown_pattern
from tracelab.viewers.tui.lazy_table import LazyTable
from tracelab.viewers.tui.source import RunSource
from tracelab.viewers.tui.trace import TracePane

ROOT = Path(__file__).resolve().parent.parent
SUPPLY = ROOT / "sample_runs" / "supply-chain"
GAME_WORDS = re.compile(r"\b(board|agents?|games?|wins?|loss(es)?|return|seed|win rate|epsilon)\b", re.I)


def bounds_by_replay(episode: int, t: int) -> tuple[dict[str, tuple[float, float]], set[str]]:
    """Every atom's bound at the end of t, replaying the changes view in seq order (independent of the
    TUI's aggregate), and the atoms whose last change up to t was made by a static fact."""
    con = open_run(SUPPLY)
    static = {f for (f,) in con.execute("SELECT fact FROM raw.facts WHERE static").fetchall()}
    bound: dict[str, tuple[float, float]] = {}
    by_static: dict[str, bool] = {}
    for atom, lo, up, kind, cause in con.execute(
            "SELECT atom, new_lower, new_upper, cause_kind, cause_id FROM changes WHERE episode = ? AND t <= ? "
            "ORDER BY seq", [episode, t]).fetchall():
        bound[atom], by_static[atom] = (lo, up), kind == 0 and cause in static
    con.close()
    return bound, {a for a, s in by_static.items() if s}


@pytest.mark.parametrize("t", [0, 3, 7])
def test_atoms_true_at_t_are_the_replayed_bounds_with_lower_above_zero(t: int) -> None:
    bound, static = bounds_by_replay(0, t)
    true = sorted(a for a, (lo, _) in bound.items() if lo > 0)
    source = RunSource(SUPPLY)
    try:
        everything = atoms_at(source, 0, t, "true", hide_static=False, limit=100_000)
        assert [r["atom"] for r in everything.rows] == true and everything.total == len(true)
        assert all((r["lower"], r["upper"]) == bound[r["atom"]] for r in everything.rows)
        dynamic = atoms_at(source, 0, t, "true", limit=100_000)
        assert [r["atom"] for r in dynamic.rows] == [a for a in true if a not in static]
        assert dynamic.static_hidden == len([a for a in true if a in static])
        first = atoms_at(source, 0, t, "true", hide_static=False, limit=25)        # bounded, says so
        assert [r["atom"] for r in first.rows] == true[:25] and first.total == len(true) and first.truncated
    finally:
        source.close()


def test_atoms_changed_at_t_and_the_filters() -> None:
    con = open_run(SUPPLY)
    changed_at_3 = {a for (a,) in con.execute("SELECT DISTINCT atom FROM changes WHERE episode = 0 AND t = 3")
                    .fetchall()}
    con.close()
    source = RunSource(SUPPLY)
    try:
        changed = atoms_at(source, 0, 3, "changed", hide_static=False, limit=100_000)
        assert {r["atom"] for r in changed.rows} == changed_at_3
        assert all((r["old_lower"], r["old_upper"]) == (0, 1) for r in changed.rows)   # became exposed, alerted
        # a predicate name and its pattern name the same atoms; a GLOB on the text picks some of them
        by_name = atoms_at(source, 0, 3, "true", "exposed")
        by_pattern = atoms_at(source, 0, 3, "true", "exposed(*)")
        assert by_name.rows == by_pattern.rows and by_name.total > 0
        assert all(r["atom"].startswith("exposed(") for r in by_name.rows)
        some = atoms_at(source, 0, 3, "true", "exposed(json-*)")
        assert 0 < some.total < by_name.total and all(r["atom"].startswith("exposed(json-") for r in some.rows)
        # a typo says what the run has, as the trace's filters do
        assert "did you mean exposed" in (unknown_pattern(source, "exposd") or "")
        assert "no node 'nosuch'" in (unknown_pattern(source, "exposed(nosuch)") or "")
        assert unknown_pattern(source, "exposed") is None
    finally:
        source.close()


def test_neighbourhood_is_the_nodes_edges_and_the_labels_on_them() -> None:
    con = open_run(SUPPLY)
    (atom_id,) = con.execute("SELECT atom FROM atoms WHERE text = 'exposed(retry-kit-ng)'").fetchone()
    edges = con.execute("SELECT source, target FROM edges WHERE 'retry-kit-ng' IN (source, target)").fetchall()
    labels = dict(con.execute(
        "SELECT arg0 || '>' || arg1, list(label ORDER BY label) FROM atoms WHERE arg1 IS NOT NULL "
        "AND 'retry-kit-ng' IN (arg0, arg1) GROUP BY ALL").fetchall())
    own = {lab for (lab,) in con.execute(
        "SELECT DISTINCT label FROM changes WHERE node = 'retry-kit-ng' AND t <= 3 AND new_lower > 0").fetchall()}
    con.close()
    source = RunSource(SUPPLY)
    try:
        hood = neighbourhood(source, 0, 3, atom_id)
    finally:
        source.close()
    assert hood.atom == "exposed(retry-kit-ng)" and [n.node for n in hood.nodes] == ["retry-kit-ng"]
    node = hood.nodes[0]
    assert {lab for lab, lo, up in node.labels} == own >= {"exposed", "package"}
    expected = {(t if s == "retry-kit-ng" else s, "out" if s == "retry-kit-ng" else "in") for s, t in edges}
    assert {(n.other, n.direction) for n in node.neighbours} == expected and node.degree == len(expected)
    for n in node.neighbours:
        pair = f"retry-kit-ng>{n.other}" if n.direction == "out" else f"{n.other}>retry-kit-ng"
        assert [lab for lab, _, _ in n.labels] == labels[pair]
        assert all((lo, up) == (1, 1) for _, lo, up in n.labels)     # the graph's attributes hold at t=3


def test_beside_the_trace_the_atoms_at_the_cursors_time_and_its_atoms_graph() -> None:
    """What stands where a game's board does: it follows the cursor, filters, toggles to the changes,
    and Enter on an atom shows only its changes in the trace; no game words on screen."""
    seen: dict[str, str] = {}

    async def body(app: Any, pilot: Any) -> None:
        pane, side = await open_trace_at(app, pilot, 3)
        assert pane.board is None and side.display                         # shown from 100 columns
        row = pane.table.cursor_row
        assert row is not None and row["t"] == 3
        text = await shown_once(app, pilot, lambda s: f"{row['atom']} at t=3" in s)
        seen["trace"] = text
        assert "atoms true at t=3" in text and f"{row['atom']} at t=3" in text
        assert re.search(r"first 500 of [\d,]+ true ·", text) and "9,725" in text and "static hidden (s)" in text
        assert "b atoms" in text and "eval games" not in text

        # the cursor moves to another timestep: the list and the neighbourhood follow
        jumps = pane.jumps
        pane.query_one("#tr-goto").value = "5"
        await pilot.press("g", "enter")
        await wait_for(pilot, lambda: pane.jumps > jumps and side.atoms is not None and side.atoms.t == 5
                       and side.hood is not None and side.hood.t == 5)
        assert side.hood.atom == pane.table.cursor_row["atom"]

        # a filter by pattern, from the side's own key; every row it lists matches
        side.table.focus()
        await pilot.press("slash")
        await wait_for(pilot, lambda: app.focused is side.query_one("#gs-filter"))
        await pilot.press(*"alert(*)", "enter")
        await wait_for(pilot, lambda: side.atoms is not None and side.atoms.rows and loaded(side.table)
                       and all(r["atom"].startswith("alert(") for r in side.atoms.rows))
        assert app.focused is side.table and not side.atoms.truncated
        text = await shown_once(app, pilot, lambda s: "matching alert(*)" in s)
        assert f"{side.atoms.total} true matching alert(*)" in text
        # the list's cursor now picks the atom whose graph is shown
        await pilot.press("down")
        picked = side.table.cursor_row["atom"]
        await wait_for(pilot, lambda: side.hood is not None and side.hood.atom == picked)

        # c: the atoms changed during t (old -> new)
        await pilot.press("c")
        await wait_for(pilot, lambda: side.atoms is not None and side.atoms.mode == "changed" and loaded(side.table))
        text = await shown_once(app, pilot, lambda s: "atoms changed at t=5" in s)
        assert "old→new" in text

        # Enter on an atom: the trace shows only its changes, the cursor on them
        atom = side.table.cursor_row
        await pilot.press("enter")
        await wait_for(pilot, lambda: pane.filter is not None and pane.filter.atom_id == atom["atom_id"]
                       and loaded(pane.table))
        assert {pane.table.row(i)["atom"] for i in range(pane.table.count)} == {atom["atom"]}
        assert app.focused is pane.table
        await pilot.press("c")                                   # c from the trace too: back to true at t
        await wait_for(pilot, lambda: side.atoms is not None and side.atoms.mode == "true" and loaded(side.table))

        # s shows the static facts in both: the graph's attributes at t=0 appear beside the trace
        await pilot.press("s")
        await wait_for(pilot, lambda: side.atoms is not None and not side.hide_static and loaded(side.table))
        assert side.atoms.static_hidden == 0

        # the other views: no game words; no Training tab, and its key says why
        await pilot.press("1")
        seen["episodes"] = await shown_once(app, pilot, lambda s: "converged" in s)
        await pilot.press("4")
        rules = app.screen.panes["rules"]
        await wait_for(pilot, lambda: rules.is_attached and loaded(rules.query_one(LazyTable)))
        seen["rules"] = await shown_once(app, pilot, lambda s: "never fired" in s)
        assert "first t" in seen["rules"] and "last t" in seen["rules"]
        await pilot.press("6")
        await pilot.pause(0.3)
        assert app.screen.query_one("TabbedContent").active == "rules"
        assert any("no training metrics" in str(n.message) for n in app._notifications)
    run_app([SUPPLY], body, (120, 34))
    for view, text in seen.items():
        body_lines = "\n".join(text.splitlines()[1:])        # the header repeats the run's command
        assert not GAME_WORDS.search(body_lines), (view, GAME_WORDS.search(body_lines), text)
    assert "Training" not in seen["episodes"].splitlines()[1]


def test_saved_queries_and_palette_commands_about_games_are_not_offered_on_a_run_without_a_board() -> None:
    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        commands = {c.title for c in app.get_system_commands(app.screen)}
        assert {"Show Trace", "Show Rules", "Saved queries"} <= commands
        assert not {"Show Training", "Next evaluation game", "Previous evaluation game"} & commands
        await pilot.press("5")
        sql = app.screen.panes["sql"]
        await wait_for(pilot, lambda: sql.is_attached and app.focused is sql.editor)
        await pilot.press("f2")
        await wait_for(pilot, lambda: type(app.screen).__name__ == "SavedQueryPicker")
        names = {q.name for q in app.screen.queries}
        assert {"rule_coverage", "firings_per_episode", "episode_summary"} <= names
        assert "actions_per_win" not in names and "steps_before_loss" not in names
    run_app([SUPPLY], body)


def test_at_80x24_the_atoms_show_on_b_and_the_cursor_row_stays_above_the_scrollbar() -> None:
    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("enter")
        pane = app.screen.query_one(TracePane)
        await wait_for(pilot, lambda: pane.filter is not None and has_rows(pane.table))
        side = pane.query_one(GraphSide)
        assert not side.display                                # no room beside the table: hidden
        await pilot.press("end")
        await wait_for(pilot, lambda: loaded(pane.table) and pane.table.cursor == pane.table.count - 1)
        await pilot.press("b")
        await wait_for(pilot, lambda: side.display and side.atoms is not None and side.hood is not None)
        row = pane.table.cursor_row
        await pilot.pause(0.3)
        text = await shown(app, pilot)
        # the cursor's change is on screen although the narrowed table scrolls sideways now
        assert pane.table.scrollable_content_region.height < pane.table.size.height
        assert any(row["node"] in line and line.lstrip().startswith(str(row["t"])) for line in text.splitlines())
        assert f"atoms true at t={row['t']}" in text
    run_app([SUPPLY], body, (80, 24))


BIG_CHANGES = 1_000_000


@pytest.fixture(scope="module")
def big_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run without a board of 1M change rows over 200k atoms and 100k timesteps (synthetic, through
    the store's writer)."""
    sys.path.insert(0, str(Path(__file__).parent))
    from store_helpers import synthetic_trace, synthetic_vocabulary

    from tracelab.store.writer import TraceWriter
    run = tmp_path_factory.mktemp("big") / "run"
    with TraceWriter(run, {"command": "pytest big reasoning"}) as w:
        w.write_vocabulary(synthetic_vocabulary(n_nodes=5000, n_atoms=200_000))
        w.begin_episode(0)
        for i in range(4):
            w.write_changes(0, synthetic_trace(BIG_CHANGES // 4, n_atoms=200_000, t0=i * 25_000, seed=i))
        w.end_episode(0, steps=100_000, outcome="stopped", t_end=99_999)
    return run


def test_a_run_of_a_million_changes_lists_a_bounded_page_of_atoms(big_run: Path) -> None:
    source = RunSource(big_run)
    try:
        assert source.board is None and source.scalar("SELECT count(*) FROM changes") == BIG_CHANGES
        tracemalloc.start()
        t0 = time.process_time()  # CPU seconds of this process and DuckDB's threads: load does not inflate them
        found = atoms_at(source, 0, 99_999, "true")
        cpu = time.process_time() - t0
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    finally:
        source.close()
    assert len(found.rows) == 500 and found.total > 90_000 and found.truncated
    assert peak < 20e6, f"{peak / 1e6:.1f} MB of Python objects for one page of atoms"
    assert cpu < 20, f"{cpu:.1f} CPU s for one page of atoms"


def test_the_atoms_beside_the_trace_of_a_million_changes(big_run: Path) -> None:
    async def body(app: Any, pilot: Any) -> None:
        pane, side = await open_trace_at(app, pilot, 99_999)
        text = await shown_once(app, pilot, lambda s: "first 500 of" in s)
        assert re.search(r"first 500 of [\d,]+ true", text)
        assert side.table.count == 500
    run_app([big_run], body, (120, 34))


def test_the_reasoning_picture_shows_what_docs_tui_md_says() -> None:
    """docs/images/tui-reasoning.png (`tracelab tui --screenshots`): the alerts at t=3 beside the trace,
    the graph around the alerted maintainer, and the why tree of that alert."""
    import asyncio

    from tracelab.viewers.tui.screenshots import _reasoning
    trace_text, why_text = (svg_text(svg) for svg in asyncio.run(_reasoning(SUPPLY)))
    assert "atoms true at t=3" in trace_text and "true matching alert" in trace_text
    assert "alert(ben-lund) at t=3" in trace_text and "maintains" in trace_text
    assert "alert(ben-lund)" in why_text and "by alert" in why_text and "critical(fast-client-plus)" in why_text


def test_reopened_the_atoms_beside_the_trace_keep_the_static_facts_shown() -> None:
    """`s` shows the static facts in the trace and in the atoms beside it; the run reopened in the session
    shows them in both again (the pane's hide_static drives both: setting it refreshes them)."""
    async def body(app: Any, pilot: Any) -> None:
        pane, side = await open_trace_at(app, pilot, 3)
        assert side.atoms.static_hidden > 0                        # hidden by default
        await pilot.press("s")
        await wait_for(pilot, lambda: side.atoms is not None and not side.hide_static and loaded(side.table))
        await wait_for(pilot, lambda: pane.filter is not None and not pane.filter.hide_static
                       and loaded(pane.table))
        await back(app, pilot)                                     # trace -> episodes
        await wait_for(pilot, lambda: app.screen.query_one("TabbedContent").active == "episodes")
        await back(app, pilot)                                     # -> Runs
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunsScreen")
        app.show_run(SUPPLY)
        await wait_for(pilot, lambda: isinstance(app.screen.panes.get("trace"), TracePane)
                       if hasattr(app.screen, "panes") else False)
        pane = app.screen.panes["trace"]
        await wait_for(pilot, lambda: pane.filter is not None and has_rows(pane.table))
        side = pane.query_one(GraphSide)
        await wait_for(pilot, lambda: side.atoms is not None and side.atoms.t == 3 and loaded(side.table))
        assert not pane.filter.hide_static and not side.hide_static and side.atoms.static_hidden == 0
    run_app([SUPPLY], body, size=(120, 34))
