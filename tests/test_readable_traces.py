"""Traces people can read (issue 27 §8): the rows of static facts (the map at t=0) hidden by default in
the trace table and the TUI's trace, with a note saying how many and how to show them; cells shown with
their (x, y) where the run declares a grid, ids as before where it does not."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from store_helpers import write_walk_run  # noqa: E402
from tui_helpers import episodes_ready, loaded, run_app, shown_once, wait_for  # noqa: E402

from tracelab.cli import main  # noqa: E402
from tracelab.store.coordinates import GRID_KEY, Grid, grid_from_config, run_grid  # noqa: E402
from tracelab.store.reader import open_run  # noqa: E402
from tracelab.viewers.tui.trace import TracePane  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
# RuleSim's `tracelab play --scenario base` (8x8), sealed: its map rows at t=0 static, cells numbered y * 8 + x
BASE = str(ROOT / "tests" / "data" / "rulesim" / "base")
NOTE = "rows of static facts hidden"


def cli(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def table_rows(out: str) -> int:
    return int(out.strip().splitlines()[-1].strip("()").split()[0].replace(",", ""))


def static_rows(run: str, episode: int) -> int:
    con = open_run(run)
    return con.execute("SELECT count(*) FROM changes c JOIN raw.facts f ON c.cause_kind = 0 AND f.fact = c.cause_id "
                       "WHERE c.episode = ? AND f.static", [episode]).fetchall()[0][0]


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(write_walk_run(tmp_path_factory.mktemp("readable") / "walk"))


def test_the_table_hides_static_facts_says_how_many_and_static_shows_them(capsys: pytest.CaptureFixture) -> None:
    hidden = static_rows(BASE, 0)
    code, out, err = cli(capsys, "trace", BASE, "-e", "0")
    assert code == 0 and err == (f"note: {hidden:,} {NOTE} (atoms set by facts declared static, such as a game's "
                                 "map or a graph's attributes, which never change); --static shows them\n")
    dynamics = table_rows(out)
    code, out, err = cli(capsys, "trace", BASE, "-e", "0", "--static")
    assert code == 0 and not err
    assert table_rows(out) == dynamics + hidden and hidden > dynamics / 2     # the map is half the rows
    assert "fact:free(" in out
    # the exports keep every row unless asked; the counts add up the same way
    _, out, err = cli(capsys, "trace", BASE, "-e", "0", "--format", "csv")
    assert out.count("\n") - 1 == dynamics + hidden and not err
    _, out, err = cli(capsys, "trace", BASE, "-e", "0", "--format", "csv", "--hide-static")
    assert out.count("\n") - 1 == dynamics and NOTE in err and "fact:free(" not in out


def test_a_filter_on_static_atoms_alone_says_why_it_shows_nothing(capsys: pytest.CaptureFixture) -> None:
    code, out, err = cli(capsys, "trace", BASE, "-e", "0", "--label", "free")
    assert code == 0 and out.strip().endswith("(0 rows)") and f"58 {NOTE}" in err   # 64 cells, 6 mountains
    code, out, _ = cli(capsys, "trace", BASE, "-e", "0", "--label", "free", "--static")
    assert table_rows(out) == 58


def test_cells_read_with_their_coordinates_in_trace_and_why(capsys: pytest.CaptureFixture) -> None:
    _, out, _ = cli(capsys, "trace", BASE, "-e", "0", "--label", "leftOf", "--static", "--limit", "400")
    assert "(29@(5,3),30@(6,3))" in out.split()              # leftOf(29,30): the id kept, then (x, y)
    _, out, _ = cli(capsys, "trace", BASE, "-e", "0", "--label", "atLoc", "--to", "0")
    assert {"(red-agent-1,7@(7,0))", "(blue-agent-1,56@(0,7))"} <= set(out.split())   # the bases
    code, out, _ = cli(capsys, "why", BASE, "atLoc(red-agent-1,5)", "-e", "0", "--at", "2", "--depth", "2")
    assert code == 0 and out.startswith("atLoc(red-agent-1,5@(5,0)) = [1,1] at the end of t=2")
    assert "Y=5@(5,0)" in out and "ok leftOf(5@(5,0),6@(6,0)):[1,1] = [1,1]" in out
    # the exports and --json keep the ids: what a script joins on
    _, out, _ = cli(capsys, "trace", BASE, "-e", "0", "--label", "atLoc", "--to", "0", "--format", "csv")
    assert "atLoc(red-agent-1,7)" in out and "@" not in out


def test_a_run_without_coordinates_reads_ids_as_before(walk: str, capsys: pytest.CaptureFixture) -> None:
    assert run_grid(open_run(walk)) is None
    code, out, err = cli(capsys, "trace", walk, "-e", "10", "--from", "2", "--to", "3")
    lines = [ln.split() for ln in out.splitlines()]
    assert code == 0 and ["2", "(r1,b)", "at", "[0,1]", "[1,1]", "go"] in lines and "@" not in out and not err
    code, out, err = cli(capsys, "trace", walk, "-e", "10")
    assert code == 0 and f"{static_rows(walk, 10)} {NOTE}" in err      # edge(a,b) ... danger(c): static
    code, out, _ = cli(capsys, "why", walk, "alarm(r1)", "-e", "10", "--at", "4")
    assert code == 0 and out.startswith("alarm(r1) = [1,1] at the end of t=4") and "@" not in out


def test_what_a_run_may_declare_as_its_grid() -> None:
    assert grid_from_config({GRID_KEY: {"width": 4, "height": 3}}) == Grid(4, 3)
    assert Grid(4, 3).with_coordinates("nextTo(11,7)") == "nextTo(11@(3,2),7@(3,1))"
    assert Grid(4, 3).with_coordinates("at(red-agent-1,12)") == "at(red-agent-1,12)"   # 12: not a cell
    assert Grid(4, 3).with_coordinates("tally(red-agent-1,q0_0)") == "tally(red-agent-1,q0_0)"
    for bad in ({"grid": {"width": 0, "height": 3}}, {"grid": {"width": "8", "height": 8}},
                {"grid": {"width": True, "height": 8}}, {"grid": {"width": 2**20, "height": 2**20}},
                {"scenario": "width = ["}, {"worlds": 3}):
        assert grid_from_config(bad) is None            # read as ids, never as wrong places
    # a RuleSim train --scenario run named its scenario and kept the TOML beside it; a play run, the TOML
    assert grid_from_config({"scenario": "base", "scenario_toml": "width = 8\nheight = 8\n"}) == Grid(8, 8)
    # ... as its registration reads it, for a run from before boards were declared only: a declared world's
    # board names its cells (c0_0), and its whole-number arguments are no cells
    assert grid_from_config({"scenario": "width = 8\nheight = 8\n"}, board=None) is None
    assert run_grid(open_run(ROOT / "tests" / "data" / "rulesim" / "base")) == Grid(8, 8)


def test_the_tui_trace_hides_static_facts_until_s_and_shows_coordinates() -> None:
    hidden = static_rows(BASE, 0)

    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("enter")                                    # episode 0's trace
        pane = app.screen.query_one(TracePane)
        table = pane.table
        await wait_for(pilot, lambda: pane.filter is not None and table.count > 0 and loaded(table))
        dynamics = table.count
        assert pane.trace is not None and pane.trace.hidden == hidden
        assert not any(str(table.row(i)["rule"]).startswith("fact:free") for i in range(min(dynamics, 200)))
        text = await shown_once(app, pilot, lambda t: f"{hidden} static hidden (s shows)" in t
                                and "(red-agent-1,7@(7,0))" in t)
        assert f"{hidden} static hidden (s shows)" in text and "(red-agent-1,7@(7,0))" in text
        jumps = pane.jumps
        await pilot.press("s")                                        # show them
        await wait_for(pilot, lambda: pane.jumps > jumps and table.count == dynamics + hidden and loaded(table))
        assert not pane.filter.hide_static and pane.trace.hidden == 0
        text = await shown_once(app, pilot, lambda t: "static hidden" not in t and "free" in t)
        assert "static hidden" not in text
        jumps = pane.jumps
        await pilot.press("s")                                        # and hide them again
        await wait_for(pilot, lambda: pane.jumps > jumps and table.count == dynamics and loaded(table))
    run_app([Path(BASE)], body, size=(130, 30))


def test_the_episode_index_hides_static_facts_as_sql_does() -> None:
    """Hiding static facts answered from the in-memory episode index: the same rows and count as SQL."""
    from dataclasses import replace

    from tracelab.viewers.tui.episode_index import episode_index
    from tracelab.viewers.tui.paging import PAGE
    from tracelab.viewers.tui.trace_paging import TraceFilter, TraceSource
    from tracelab.viewers.tui.source import RunSource
    source = RunSource(BASE)
    static = static_rows(BASE, 0)
    for flt, hidden in ((TraceFilter(0, hide_static=True), static),
                        (TraceFilter(0, label="leftOf", hide_static=True), 56),      # 8x8: 7 pairs a row
                        (TraceFilter(0, rule="fact:*", t_to=0, hide_static=True), static)):
        by_sql = TraceSource(source, flt)
        count = by_sql.prepare()
        assert by_sql.hidden == hidden
        assert count == TraceSource(source, replace(flt, hide_static=False)).prepare() - hidden
        assert episode_index(source, 0) is not None
        indexed = TraceSource(source, flt)
        assert indexed.prepare() == count and indexed.anchors is not None and indexed.hidden == hidden
        pages = (count + PAGE - 1) // PAGE
        assert [r["seq"] for p in range(pages) for r in indexed.fetch(p)] == \
               [r["seq"] for p in range(pages) for r in by_sql.fetch(p)]
