"""The board rebuilt from a run's trace (viewers/board.py) against the hand-written simulator and
the run's own `steps` rows, on the sample runs (base 1v1, advanced 1v1 with shooting, nonmarkov 2v2
with slow agents)."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from tracelab.game.refsim import RefSim
from tracelab.game.scenario import scenario_from_dict
from tracelab.viewers.board import PHASES, BoardLoader, EpisodeBoard, load_episode
from tracelab.store.reader import open_run

SAMPLES = Path(__file__).resolve().parent.parent / "sample_runs"
RUNS = ("base", "advanced", "nonmarkov")


def _played(con) -> list[int]:
    return [e for (e,) in con.execute("SELECT episode FROM episodes WHERE steps > 0 ORDER BY 1").fetchall()]


@pytest.fixture(scope="module", params=RUNS)
def run(request: pytest.FixtureRequest):
    con = open_run(SAMPLES / request.param)
    config = json.loads(con.execute("SELECT config FROM run").fetchall()[0][0])
    scenario = scenario_from_dict(tomllib.loads(config["scenario"]), request.param)
    return con, scenario, {e: load_episode(con, e) for e in _played(con)}


def test_the_map_comes_from_the_runs_facts(run) -> None:
    _, scenario, boards = run
    board = next(iter(boards.values()))
    assert (board.map.width, board.map.height) == (scenario.width, scenario.height)
    assert sorted(map(tuple, board.map.mountains.tolist())) == sorted(scenario.mountains)
    assert [tuple(b) for b in board.map.bases.tolist()] == list(scenario.bases)
    n = scenario.agents_per_team
    assert board.agents == [f"{t}-agent-{j + 1}" for t in ("red", "blue") for j in range(n)]
    assert len(board.bullets) == 2 * n * scenario.ammo


def test_replaying_the_boards_actions_in_refsim_gives_the_same_board(run) -> None:
    """Every step's agents and bullets agree with RefSim fed the actions the board read from the trace."""
    _, scenario, boards = run
    n = scenario.agents_per_team
    for episode, board in boards.items():
        sim = RefSim(scenario)
        sim.reset()
        assert board.steps >= 1
        for s in range(1, board.steps + 1):
            acts = board.action[s].reshape(2, n)
            r = sim.step(acts[0][None], acts[1][None])
            where = f"episode {episode} step {s}"
            np.testing.assert_array_equal(board.alive[s], r.alive[0].reshape(-1), where)
            pos = r.positions[0].reshape(-1, 2)
            np.testing.assert_array_equal(board.agent_x[s], pos[:, 0], where)
            np.testing.assert_array_equal(board.agent_y[s], pos[:, 1], where)
            np.testing.assert_allclose(board.health[s], r.health[0].reshape(-1), err_msg=where)
            np.testing.assert_array_equal(board.ammo[s], r.ammo[0].reshape(-1), where)
            bx, by = board.map.xy(board.bullet_cell[s])
            np.testing.assert_array_equal(np.stack([bx, by], 1), r.bullet_pos[0], where)
            np.testing.assert_array_equal(board.bullet_dir[s], r.bullet_dir[0], where)
        assert r.terminated[0] or r.truncated[0]


def test_positions_and_actions_agree_with_the_runs_steps_rows(run) -> None:
    con, scenario, boards = run
    n = scenario.agents_per_team
    for episode, board in boards.items():
        rows = con.execute("SELECT step, agent, action, obs FROM steps WHERE episode = ? "
                           "ORDER BY step, agent", [episode]).fetchall()
        assert len(rows) == board.steps * 2 * n
        for step, agent, action, obs in rows:
            i = board.agents.index(agent)
            assert board.action[step, i] == action, (episode, step, agent)   # spec ids
            if agent.startswith("red-"):    # a red row's observation: red's positions, then blue's
                xy = np.asarray(obs[:4 * n]).reshape(-1, 2)
                alive = board.alive[step]
                np.testing.assert_array_equal(np.where(alive, board.agent_x[step], -1), xy[:, 0])
                np.testing.assert_array_equal(np.where(alive, board.agent_y[step], -1), xy[:, 1])


def _advanced_ep0() -> EpisodeBoard:
    return load_episode(open_run(SAMPLES / "advanced"), 0)


def test_phases_within_a_step_show_the_order_of_the_game() -> None:
    """Advanced episode 0, step 15: blue's bullet flies from (5,3) onto red's cell (4,3) and hits;
    red dies in the deaths phase; blue moves up in the act phase."""
    b = _advanced_ep0()
    ph = {name: i for i, name in enumerate(PHASES)}
    bullet = b.bullets.index("blue-bullet-1-1")
    assert b.map.xy(b.phase_bullet_cell[15, ph["start"], bullet]) == (5, 3)
    assert b.phase_bullet_cell[15, ph["bullets"], bullet] == -1          # hit, then removed
    red, blue = b.agents.index("red-agent-1"), b.agents.index("blue-agent-1")
    assert b.phase_alive[15, ph["walk-in"], red] and not b.phase_alive[15, ph["deaths"], red]
    assert b.map.xy(b.phase_agent_cell[15, ph["hits"], blue]) == (7, 3)
    assert b.map.xy(b.phase_agent_cell[15, ph["act"], blue]) == (7, 4)
    assert b.outcome == "loss"


def test_frame_and_firings_of_one_step() -> None:
    b = _advanced_ep0()
    frame = b.frame(15)
    red = next(a for a in frame.agents if a.name == "red-agent-1")
    assert (red.x, red.y, red.alive, red.health, red.ammo) == (4, 3, False, 0.0, 0)
    hit = [f for f in frame.firings if f["rule"] == "b_hit"]
    assert len(hit) == 1 and hit[0]["head"] == "struck(blue-bullet-1-1,red-agent-1)"
    assert hit[0]["phase"] == "bullets" and hit[0]["cell"] == 3 * 8 + 4 and hit[0]["new"] == [1.0, 1.0]
    rows = b.firings.at(15)
    assert len(rows) == len(frame.firings) and (np.diff(b.firings.seq[rows]) > 0).all()
    killed = [i for i in rows if b.firings.rule[i] == "d_killed"]
    assert b.firings.agent[killed[0]] == b.agents.index("red-agent-1")
    assert b.frame(15, phase=PHASES.index("start")).agents[0].alive
    with pytest.raises(IndexError):
        b.frame(b.steps + 1)


def test_an_episode_without_rows_is_a_key_error() -> None:
    with pytest.raises(KeyError, match="episode 99"):
        load_episode(open_run(SAMPLES / "advanced"), 99)


def test_prefetched_episodes_load_the_same_boards_as_one_at_a_time(run) -> None:
    """BoardLoader.prefetch reads several episodes in one query each; the boards must not change."""
    con, _, boards = run
    loader = BoardLoader(con)
    groundings = loader.prefetch(list(boards) + [99])             # 99: no rows, nothing to hand out
    named = np.concatenate([b.changes["grounding"] for b in boards.values()])
    assert set(groundings.tolist()) == set(named.tolist())
    for e, alone in boards.items():
        batched = loader.load(e)
        assert batched.outcome == alone.outcome
        for name in ("phase_agent_cell", "phase_alive", "phase_health", "phase_ammo", "phase_bullet_cell",
                     "phase_bullet_dir", "action"):
            np.testing.assert_array_equal(getattr(batched, name), getattr(alone, name), err_msg=name)
        f, g = batched.firings, alone.firings
        assert (f.rule, f.bindings, f.head) == (g.rule, g.bindings, g.head)
        np.testing.assert_array_equal(f.cell, g.cell)
        np.testing.assert_array_equal(loader.load(e).action, alone.action)   # handed out once, then read again
    with pytest.raises(KeyError, match="episode 99"):
        loader.load(99)
