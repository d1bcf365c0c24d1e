"""The agent's decision beside the board in the TUI's trace (viewers/tui/decision.py), on the real sample
runs: a training run's traced evaluation game (sample_runs/base-train: its policy's Q-values recorded)
shows, at the cursor's step, a bar per action with the values the run stores, the chosen action marked,
masked actions as masked and the step's reward terms; `d` then `w` open `why --action` in the Why view;
a run played by the scripted policy (sample_runs/base: no decisions) shows no panel and offers no `d`."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from tui_helpers import episodes_ready, has_rows, loaded, run_app, wait_for

from tracelab.store.reader import open_run
from tracelab.viewers.tui.decision import DecisionPanel, draw
from tracelab.viewers.tui.trace import TracePane
from tracelab.viewers.tui.why import WhyPane

ROOT = Path(__file__).resolve().parent.parent
TRAINED = ROOT / "sample_runs" / "base-train"
SCRIPTED = ROOT / "sample_runs" / "base"
SIZE = (120, 34)


async def trace_at(app: Any, pilot: Any, t: int) -> TracePane:
    """The first traced episode's trace (a training run's: its first evaluation game) at timestep t."""
    await episodes_ready(app, pilot)
    await pilot.press("enter")
    pane = app.screen.query_one(TracePane)
    await wait_for(pilot, lambda: pane.filter is not None and loaded(pane.table))
    if pane.table.count == 0:
        await pilot.press("right_square_bracket")
        await wait_for(pilot, lambda: has_rows(pane.table))
    jumps = pane.jumps
    pane.query_one("#tr-goto").value = str(t)
    await pilot.press("g", "enter")
    await wait_for(pilot, lambda: pane.jumps > jumps and loaded(pane.table)
                   and int(pane.table.cursor_row["t"]) == t)
    return pane


def stored_decision(episode: int, step: int) -> dict[str, Any]:
    con = open_run(TRAINED)
    try:
        rows = con.execute("SELECT agent, action_name, actions, \"values\", mask FROM decisions "
                           "WHERE episode = ? AND step = ?", [episode, step]).fetchall()
        terms = con.execute("SELECT term, value FROM rewards WHERE episode = ? AND step = ? AND agent = ?",
                            [episode, step, rows[0][0]]).fetchall()
    finally:
        con.close()
    assert len(rows) == 1, rows    # the trained red agent decides; blue is the scripted opponent
    agent, chosen, actions, values, mask = rows[0]
    return {"agent": agent, "chosen": chosen, "values": dict(zip(actions, values)),
            "allowed": dict(zip(actions, mask or [True] * len(actions))), "terms": dict(terms)}


def test_the_decision_of_the_cursors_step_beside_the_board_and_w_explains_it() -> None:
    async def body(app: Any, pilot: Any) -> None:
        pane = await trace_at(app, pilot, 10)
        panel = pane.query_one(DecisionPanel)
        await wait_for(pilot, lambda: panel.display and panel.step is not None and panel.step.step == 10)
        episode = pane.filter.episode
        stored = stored_decision(episode, 10)
        (shown,) = panel.step.decisions
        assert shown.agent == stored["agent"] and shown.action == stored["chosen"]
        assert {a.name: a.value for a in shown.ranked} == stored["values"]
        assert {a.name: a.allowed for a in shown.ranked} == stored["allowed"]
        assert dict(shown.terms) == stored["terms"]
        text = draw(panel.step, 20, None).plain.splitlines()
        marked = [line for line in text if line.startswith("▶")]
        assert len(marked) == 1 and marked[0][1:].split()[0] == stored["chosen"]
        masked = {n for n, ok in stored["allowed"].items() if not ok}
        assert {line[1:].split()[0] for line in text if line.endswith("masked")} == masked
        assert any(line.startswith("reward ") for line in text)
        # the board and the panel show the same step: the board's action line is the chosen one's
        assert pane.board is not None and pane.board.step == 10
        # the panel follows the cursor: another step, another decision
        jumps = pane.jumps
        pane.query_one("#tr-goto").value = "11"
        await pilot.press("g", "enter")
        await wait_for(pilot, lambda: pane.jumps > jumps and panel.step is not None and panel.step.step == 11)
        assert panel.step.decisions[0].action == stored_decision(episode, 11)["chosen"]

        # d: into the panel; down: the second-ranked action; w: the decision's why and that action's why-not
        await pilot.press("d")
        await wait_for(pilot, lambda: app.focused is panel)
        await pilot.press("down", "w")
        why = app.screen.panes["why"]
        assert isinstance(why, WhyPane)
        await wait_for(pilot, lambda: why.is_attached and why.action is not None and why.action.step == 11)
        tree = why.query_one("Tree")
        root = tree.root.label.plain
        assert root.startswith(f"{stored['agent']} at step 11 of episode {episode}: ")
        second = panel.step.decisions[0].ranked[1].name
        sections = [str(n.label) for n in tree.root.children]
        assert any(s.startswith(f"why not {second}: ") for s in sections), sections
        assert any(s.startswith("actions by Q-value") for s in sections)
    run_app([TRAINED], body, SIZE)


def test_a_run_without_decisions_shows_no_panel_and_no_error() -> None:
    async def body(app: Any, pilot: Any) -> None:
        pane = await trace_at(app, pilot, 10)
        await wait_for(pilot, lambda: pane.board is not None and pane.board.board is not None)
        panel = pane.query_one(DecisionPanel)
        await wait_for(pilot, lambda: panel.step is not None and panel.step.step == 10)
        assert not panel.display
        assert panel.step is None or panel.step.decisions == ()
        assert not pane.check_action("focus_decision", ())
        await pilot.press("d")                  # nothing to move into: the trace keeps the focus
        assert app.focused is pane.table
    run_app([SCRIPTED], body, SIZE)
