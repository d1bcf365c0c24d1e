"""The reading commands on a `tracelab play --env` run: the TUI (beside the trace, the spec's board with
the agent's mark at the cursor's t) and the replay, on a real recorded run."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from tui_helpers import episodes_ready, run_app, trace_at, wait_for

from tracelab.cli import main
from tracelab.store import open_run
from tracelab.board import board_of_config
from tracelab.viewers.tui.board import BoardView
from tracelab.viewers.tui.graph_side import GraphSide


@pytest.fixture(scope="module")
def lake(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run = tmp_path_factory.mktemp("lake") / "run"
    assert main(["play", "--env", "tracelab/FrozenLake-v1", "--episodes", "6", "--seed", "1", "--run", str(run)]) == 0
    return run


def test_the_tui_shows_where_the_agent_stands_at_the_cursors_step(lake: Path) -> None:
    con = open_run(lake)
    cell = int(con.execute("SELECT obs[1] FROM steps WHERE episode = 0 AND step = 1").fetchone()[0])
    con.close()
    want = f"at(c{cell // 4}_{cell % 4})"  # the observation is row * 4 + col on the 4x4 lake
    seen: dict[str, Any] = {}

    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        pane = await trace_at(app, pilot, 1)
        assert not pane.query(GraphSide)          # a world with a [board]: the board beside the trace
        board = pane.query_one(BoardView)
        await wait_for(pilot, lambda: board.board is not None and board.step == 1)
        seen["marked"], seen["text"] = board.board.at(1).marked, board.render().plain
    run_app([lake], body, (120, 34))
    # the board: the 4x4 lake's rows, `@` on the agent's cell
    assert seen["marked"] == {want[3:-1]: "at"}
    rows = [list(r) for r in ("SFFF", "FHFH", "FFFH", "HFFG")]
    rows[cell // 4][cell % 4] = "@"
    assert seen["text"] == "\n".join("".join(r) for r in rows)


def test_the_replay_writes_a_recording_of_a_game(lake: Path, tmp_path: Path) -> None:
    out = tmp_path / "lake.rrd"
    assert main(["replay", str(lake), "--episode", "0", "--save", str(out)]) == 0
    assert out.stat().st_size > 1000


def test_a_board_declaration_from_elsewhere_is_checked_before_it_is_drawn() -> None:
    good = {"rows": ["SF", "HG"], "cell": "c{row}_{col}", "marks": {"at": "@"}}
    assert board_of_config({"declared_board": good}).cell(1, 0) == "c1_0"
    for bad in ({**good, "rows": "SF"}, {**good, "rows": ["x" * 300]}, {**good, "marks": {"at": "@@"}},
                {**good, "cell": 3}, {**good, "marks": {"__import__('os')": "@"}}):
        assert board_of_config({"declared_board": bad}) is None
    # the cell format is the spec's: {row} and {col} only, never a format's field of a stranger's
    for sneaky in ("{row.__class__}_{col}", "c{row:>999999999}_{col}"):
        assert board_of_config({"declared_board": {**good, "cell": sneaky}}) is None
