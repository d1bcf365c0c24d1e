"""A run's board from its spec's `[board]` (viewers/board_state.py, tracelab/board.py's pieces): the GridWar
sample runs (RuleSim runs with no spec among their sources) drawn from rules/gridworld/war.toml, each
step's agents and bullets held against RefSim fed the actions of the run's `steps` rows; the `[board]`
pieces' errors located."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest

from tracelab.board import board_config, board_of_config
from tracelab.envs.declared.spec import SpecError, load_spec
from tracelab.game.refsim import RefSim
from tracelab.game.scenario import scenario_from_dict
from tracelab.store.reader import open_run
from tracelab.envs.declared.gridwar import WAR_SPEC
from tracelab.viewers.board_state import BoardTrack, board_of_run

SAMPLES = Path(__file__).resolve().parent.parent / "sample_runs"
RULESIM = Path(__file__).resolve().parent / "data" / "rulesim"   # runs RuleSim wrote (the sample runs until 2026-11-29)


@pytest.mark.parametrize("name", ["base"])
def test_a_gridwar_runs_board_is_war_toml_and_agrees_with_refsim(name: str) -> None:
    """A RuleSim run (its cells numbered, no spec in its config) drawn with war.toml's board: every agent and
    bullet where RefSim, replaying the run's recorded actions, puts it."""
    con = open_run(RULESIM / name)
    config = json.loads(con.execute("SELECT config FROM run").fetchall()[0][0])
    scenario = scenario_from_dict(tomllib.loads(config["scenario"]), name)
    board = board_of_run(con)
    assert board is not None and board.rows == load_spec(WAR_SPEC).board.rows   # war.toml's default map
    assert set(board.pieces) == {"agents", "bullets"}
    n = scenario.agents_per_team
    agents = [f"{t}-agent-{j + 1}" for t in ("red", "blue") for j in range(n)]
    episodes = [e for (e,) in con.execute("SELECT episode FROM episodes WHERE steps > 0 ORDER BY 1").fetchall()]
    for episode in episodes:
        track = BoardTrack.read(con, board, episode)
        rows = con.execute("SELECT step, agent, action FROM steps WHERE episode = ? ORDER BY step",
                           [episode]).fetchall()
        actions = {(s, a): act for s, a, act in rows}
        sim = RefSim(scenario)
        sim.reset()
        for s in range(1, max(s for s, _, _ in rows) + 1):
            acts = [[actions[(s, a)] for a in agents[:n]], [actions[(s, a)] for a in agents[n:]]]
            r = sim.step([acts[0]], [acts[1]])
            state = track.at(s)
            on_board = {p.thing: p for p in state.pieces if p.kind == "agents"}
            for i, a in enumerate(agents):
                x, y = r.positions[0].reshape(-1, 2)[i]
                p = on_board[a]
                assert (p.col, board.height - 1 - p.row, p.alive) == (x, y, bool(r.alive[0].reshape(-1)[i])), \
                    (name, episode, s, a)
            flying = sorted((p.col, board.height - 1 - p.row, p.arrow) for p in state.pieces if p.kind == "bullets")
            arrows = "↑↓←→"
            want = sorted((int(x), int(y), arrows[d]) for (x, y), d in zip(r.bullet_pos[0].tolist(),
                                                                             r.bullet_dir[0].tolist()) if x >= 0)
            assert flying == want, (name, episode, s)


def test_the_pieces_go_through_the_runs_config() -> None:
    board = load_spec(WAR_SPEC).board
    again = board_of_config({"declared_board": json.loads(json.dumps(board_config(board)))})
    assert again is not None and again.pieces == board.pieces and again.annotate == board.annotate
    bad = board_config(board)
    bad["pieces"]["agents"]["at"] = "atLoc(x)"          # a stranger's config: refused, not drawn wrong
    assert board_of_config({"declared_board": bad}) is None


@pytest.mark.parametrize("line, where", [
    ('pieces.agents = { at = "nowhere", things = "agent" }', "board.pieces.agents.at"),
    ('pieces.agents = { at = "atLoc", things = "agent", alive = "team" }', "board.pieces.agents.alive"),
    ('pieces.agents = { at = "atLoc", things = "agent", colors = { "red-" = "red" } }',
     "board.pieces.agents.colors.red-"),
    ('pieces.agents = { at = "atLoc", thing = "agent" }', "board.pieces.agents"),
    ('annotate = ["struck", "nosuch"]', "board.annotate[1]"),
])
def test_a_bad_piece_is_a_located_error(tmp_path: Path, line: str, where: str) -> None:
    text = WAR_SPEC.read_text()
    head, tail = text.split("\n[agents]", 1)
    head = "\n".join(x for x in head.splitlines() if not x.startswith(("pieces.", "annotate")))
    spec = tmp_path / "war.toml"
    spec.write_text(f"{head}\n{line}\n\n[agents]{tail}")
    for rules in WAR_SPEC.parent.glob("*.rules"):
        (tmp_path / rules.name).write_text(rules.read_text())
    with pytest.raises(SpecError) as e:
        load_spec(spec)
    assert "war.toml:" in str(e.value) and where in str(e.value)


def test_a_training_runs_evaluation_game_has_its_agents_on_the_board() -> None:
    """sample_runs/base-train (trained through war.toml): its traced evaluation game drawn on the spec's
    board, red-agent-1 on the cell c{row}_{col} the trace's first atLoc names."""
    con = open_run(SAMPLES / "base-train")
    board = board_of_run(con)
    episode = con.execute("SELECT min(episode) FROM episodes WHERE json_extract_string(begin_info, '$.kind') = 'eval' "
                          "AND steps > 0 AND episode IN (SELECT DISTINCT episode FROM raw.changes)").fetchall()[0][0]
    cell = con.execute("SELECT n1.name FROM raw.changes c JOIN raw.atoms a USING (atom) "
                       "JOIN raw.labels l USING (label) JOIN raw.nodes n0 ON n0.node = a.arg0 "
                       "JOIN raw.nodes n1 ON n1.node = a.arg1 WHERE l.name = 'atLoc' "
                       "AND n0.name = 'red-agent-1' AND c.episode = ? AND c.t = 1 AND c.new_lower = 1",
                       [episode]).fetchall()[0][0]
    red = next(p for p in BoardTrack.read(con, board, episode).at(1).pieces if p.thing == "red-agent-1")
    assert f"c{red.row}_{red.col}" == cell


def test_a_scenario_too_big_or_not_a_grid_gives_no_board() -> None:
    """A RuleSim run's config is a stranger's: a side past the recorded limit is no board (drawn as the
    run's graph), not a grid built to its size."""
    from tracelab.world_extras import old_run_board
    text = 'width = {w}\nheight = 8\nred_base = [0, 0]\nblue_base = [1, 1]\n'
    assert old_run_board("gridworld", {"scenario": text.format(w=8)}) is not None
    assert old_run_board("another", {"scenario": text.format(w=8)}) is None  # not a RuleSim run's board
    for w in (100_000, 0, -3):
        assert old_run_board("gridworld", {"scenario": text.format(w=w)}) is None
