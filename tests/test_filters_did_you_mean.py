"""Filters and names that match nothing in a run say so, the same way everywhere (issue 27 §4): one line
`no KIND 'NAME' in this run; did you mean ...?` from tracelab.store.names, in trace, why, why-not, replay
and the TUI's trace filters, instead of an empty table with exit 0."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from tracelab.cli import main  # noqa: E402
from tracelab.store.names import UnknownName, check_name  # noqa: E402
from tracelab.store.reader import open_run  # noqa: E402
from tracelab.viewers.tui.lazy_table import LazyTable  # noqa: E402
from tracelab.viewers.tui.trace import TracePane  # noqa: E402
from tui_helpers import episodes_ready, loaded, run_app, wait_for  # noqa: E402

ADVANCED = str(Path(__file__).resolve().parents[1] / "sample_runs" / "advanced")


def cli(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize("argv, message", [
    (["trace", ADVANCED, "-e", "0", "--rule", "d_kiled"],
     "no rule 'd_kiled' in this run; did you mean d_killed, h_killed?"),
    (["trace", ADVANCED, "-e", "0", "--atom", "alive(red_agent_1)"],
     "no node 'red_agent_1' in this run; did you mean red-agent-1, blue-agent-1?"),
    (["trace", ADVANCED, "-e", "0", "--atom", "aliv(*)"], "no label 'aliv' in this run; did you mean alive?"),
    (["trace", ADVANCED, "-e", "0", "--label", "aliv"], "no label 'aliv' in this run; did you mean alive?"),
    (["why", ADVANCED, "alive(red_agent_1)", "-e", "0"],
     "no node 'red_agent_1' in this run; did you mean red-agent-1, blue-agent-1?"),
    (["why", ADVANCED, "aliv(red-agent-1)", "-e", "0"], "no label 'aliv' in this run; did you mean alive?"),
    (["why-not", ADVANCED, "-e", "0", "--rule", "d_kiled", "--at", "3"],
     "no rule 'd_kiled' in this run; did you mean d_killed, h_killed?"),
    (["why-not", ADVANCED, "-e", "0", "--rule", "d_killed", "--grounding", "A=red_agent_1", "--at", "3"],
     "no node 'red_agent_1' in this run; did you mean red-agent-1, blue-agent-1?"),
    (["replay", ADVANCED, "--lanes", "aliv,ammo"], "no predicate 'aliv' in this run (--lanes); did you mean alive?"),
    (["replay", ADVANCED, "--outcome", "wn"], "no outcome 'wn'; did you mean win?"),
])
def test_an_unknown_name_is_one_line_with_the_close_names(argv: list[str], message: str,
                                                          capsys: pytest.CaptureFixture) -> None:
    code, out, err = cli(capsys, *argv)
    assert (code, out, err) == (1, "", f"tracelab: error: {message}\n")


def test_an_atom_pattern_without_a_match_says_how_to_write_one(capsys: pytest.CaptureFixture) -> None:
    code, _, err = cli(capsys, "trace", ADVANCED, "-e", "0", "--atom", "alive")
    assert code == 1 and err == ("tracelab: error: no atom matches 'alive' in this run; write an atom as "
                                 "label(args) with * for any part, e.g. alive(*)\n")
    code, _, err = cli(capsys, "trace", ADVANCED, "-e", "0", "--atom", "atLoc(red-agent-1,c6_6,c6_5)")
    assert code == 1 and "did you mean atLoc(red-agent-1,c6_6), " in err and "e.g. atLoc(*)" in err


def test_filters_that_match_still_print_their_rows(capsys: pytest.CaptureFixture) -> None:
    code, out, err = cli(capsys, "trace", ADVANCED, "-e", "0", "--rule", "act*", "--atom", "alive(*)",
                         "--label", "al*", "--to", "0", "--format", "csv")
    # the header and both agents' alive start facts, each cleared at the reset and set
    assert code == 0 and not err and out.count("\n") == 5


def test_check_name_accepts_globs_and_every_cause_name() -> None:
    con = open_run(ADVANCED)
    for kind, pattern in (("cause", "d_killed"), ("cause", "fact:*"), ("cause", "action"), ("cause", "reset"),
                          ("label", "at*"), ("node", "red-agent-?"), ("atom", "atLoc(red-agent-1,*)")):
        check_name(con, kind, pattern)
    nodes = r"^no node 'zz' in this run; its nodes: blue, blue-agent-1, .* \(99 in all\)$"
    with pytest.raises(UnknownName, match=nodes):
        check_name(con, "node", "zz")


def test_the_tui_trace_filter_names_a_typo_and_how_to_write_an_atom() -> None:
    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("enter")                                       # episode 0's trace
        trace = app.screen.query_one("#tr-table", LazyTable)
        await wait_for(pilot, lambda: trace.count > 0 and loaded(trace))
        pane = app.screen.query_one(TracePane)
        status = pane.query_one("#tr-status")

        async def filter_by(field: str, value: str) -> None:
            pane.query_one(field).value = value
            await pilot.press("slash", "enter")
            await wait_for(pilot, lambda: loaded(trace) and pane.jumps > jumps)

        jumps = pane.jumps
        await filter_by("#tr-atom", "alive")
        expected = ("no atom matches 'alive' in this run; write an atom as label(args) with * for any part, "
                    "e.g. alive(*)")
        assert trace.count == 0 and trace.error == expected and expected in str(status.render())
        jumps = pane.jumps
        await filter_by("#tr-atom", "alive(*)")
        assert trace.count > 0 and trace.error is None and "alive(*)" in str(status.render())
        jumps = pane.jumps
        await filter_by("#tr-rule", "d_kiled")
        assert trace.error == "no rule 'd_kiled' in this run; did you mean d_killed, h_killed?"
    run_app([Path(ADVANCED)], body)
