"""The reading commands on a `tracelab play --env` run: the TUI (the atoms true at the cursor's t beside
the trace: a declared run has no board the viewers draw yet) and the replay, on a real recorded run."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from tui_helpers import open_trace_at, run_app

from tracelab.cli import main
from tracelab.store import open_run


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
        _, side = await open_trace_at(app, pilot, 1)
        seen["atoms"] = [r["atom"] for r in side.atoms.rows]
    run_app([lake], body, (120, 34))
    assert want in seen["atoms"] and sum(a.startswith("at(") for a in seen["atoms"]) == 1


def test_the_replay_writes_a_recording_of_a_game(lake: Path, tmp_path: Path) -> None:
    out = tmp_path / "lake.rrd"
    assert main(["replay", str(lake), "--episode", "0", "--save", str(out)]) == 0
    assert out.stat().st_size > 1000
