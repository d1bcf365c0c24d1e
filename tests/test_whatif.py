"""`tracelab whatif RUN --episode E --at T --action NAME` (issue 39 item 4), on a toy-text world
(FrozenLake, slippery: its draws come from the seeded stream that play's later games continue) and on
GridWar's base scenario as a spec (rules/gridworld/war.toml, masked actions): the recorded action
reproduces the episode exactly (every step's row, reward terms and change rows), another action diverges
at T; `diff` of the branch against its origin picks the episode with no arguments; the run catalog marks
the branch; a user error is one line and writes nothing."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from store_helpers import run_rows as rows

from tracelab.cli import main
from tracelab.store import open_run
from tracelab.store.catalog import list_runs
from tracelab.store.diff import first_divergence

ROOT = Path(__file__).resolve().parents[1]
WORLDS = {"frozen": (["--env", "tracelab/FrozenLake-v1", "--episodes", "4", "--seed", "3"], 2),
          "war": (["--scenario", "base", "--episodes", "2", "--seed", "1"], 1)}  # GridWar through its spec


@pytest.fixture(scope="module")
def origins(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("whatif")
    out = {}
    for name, (flags, _) in WORLDS.items():
        out[name] = folder / name
        assert main(["play", *flags, "--run", str(out[name])]) == 0
    return out


def steps_of(run: Path, episode: int) -> list[tuple]:
    return rows(run, "SELECT step, t, agent, action, reward, terminated, truncated, obs FROM raw.steps "
                     f"WHERE episode = {episode} ORDER BY step, agent")


def terms_of(run: Path, episode: int) -> list[tuple]:
    return rows(run, f"SELECT step, agent, term, value FROM rewards WHERE episode = {episode} ORDER BY ALL")


def changes_of(run: Path, episode: int) -> list[tuple]:
    return rows(run, "SELECT t, pass_no, atom, old_lower, old_upper, new_lower, new_upper, rule FROM changes "
                     f"WHERE episode = {episode} ORDER BY t, pass_no, atom, rule, new_lower")


def action_names(run: Path, episode: int) -> list[str]:
    return [a for (a,) in rows(run, f"SELECT action_name FROM steps WHERE episode = {episode} ORDER BY step")]


def branch(origin: Path, out: Path, episode: int, at: int, action: str, *more: str) -> Path:
    assert main(["whatif", str(origin), "--episode", str(episode), "--at", str(at), "--action", action,
                 "--run", str(out), *more]) == 0
    return out


def divergence(origin: Path, episode: int, run: Path):  # noqa: ANN201 - diff.Divergence
    a, b = open_run(origin), open_run(run)
    try:
        return first_divergence(a, episode, 0, b, run_names=("origin", "branch"))
    finally:
        a.close()
        b.close()


@pytest.mark.parametrize("world", WORLDS)
def test_the_recorded_action_reproduces_the_episode_exactly(world: str, origins: dict[str, Path], tmp_path: Path,
                                                            capsys: pytest.CaptureFixture) -> None:
    origin, episode = origins[world], WORLDS[world][1]
    names = action_names(origin, episode)
    at = max(1, len(names) // 2)
    run = branch(origin, tmp_path / "same", episode, at, names[at - 1])
    assert "no divergence" in capsys.readouterr().out
    assert steps_of(run, 0) == steps_of(origin, episode) and len(steps_of(run, 0)) == len(names)
    assert terms_of(run, 0) == terms_of(origin, episode)
    assert changes_of(run, 0) == changes_of(origin, episode)
    assert divergence(origin, episode, run).identical
    assert rows(run, "SELECT outcome, reward FROM episodes") == \
        rows(origin, f"SELECT outcome, reward FROM episodes WHERE episode = {episode}")


@pytest.mark.parametrize("world", WORLDS)
def test_another_action_diverges_at_its_step(world: str, origins: dict[str, Path], tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    origin, episode = origins[world], WORLDS[world][1]
    names = action_names(origin, episode)
    # a step whose recorded action is a move; `nothing` (war) is allowed wherever the agent can act
    at = next(k for k, a in enumerate(names, 1) if k > 1 and a not in ("nothing", "left"))
    other = "nothing" if world == "war" else "left"
    run = branch(origin, tmp_path / "other", episode, at, other, "--steps", "2")
    out = capsys.readouterr().out
    played = steps_of(run, 0)
    assert len(played) <= at + 2  # --steps 2: at most two steps after the branch
    if not (played[-1][5] or played[-1][6]):  # neither terminated nor truncated: stopped, and says so
        assert "the branch stopped before its end: --steps 2 played after step" in out
        assert rows(run, "SELECT outcome FROM episodes") == [("aborted",)]
    assert f"({other} instead of {names[at - 1]})" in out and f"first divergence of the trace: {at} steps in" in out
    d = divergence(origin, episode, run)
    assert d.rel_t == at and d.first_action_difference["step"] == at
    assert steps_of(run, 0)[:at - 1] == steps_of(origin, episode)[:at - 1]
    assert action_names(run, 0)[at - 1] == other
    # the branch names its origin: the catalog marks it, and diff picks the origin's episode by itself
    listed = {r.path.name: r.as_row()["scenario"] for r in list_runs([tmp_path])}
    assert listed["other"] == f"branch of {world}:{episode} at step {at} ({other} instead of {names[at - 1]})"
    assert main(["diff", str(run), str(origin)]) == 0
    assert capsys.readouterr().out.startswith(f"episodes {run}:0 (")
    if world == "frozen":  # the TUI's run list shows the catalog's rows
        tui_lists(tmp_path, listed["other"])


def tui_lists(root: Path, scenario: str) -> None:
    from tui_helpers import loaded, run_app, wait_for

    from tracelab.viewers.tui.lazy_table import LazyTable

    async def body(app: Any, pilot: Any) -> None:
        table = app.screen.query_one(LazyTable)
        await wait_for(pilot, lambda: loaded(table) and table.count == 1)
        assert table.row(0)["scenario"] == scenario
    run_app([root], body, size=(200, 24))


@pytest.mark.parametrize("world, flags, message", [
    ("frozen", ["--episode", "9", "--at", "1", "--action", "left"], "no episode 9 (its episodes: 0..3)"),
    ("frozen", ["--episode", "0", "--at", "999", "--action", "left"], "--at 999: episode 0 has "),
    ("frozen", ["--episode", "0", "--at", "1", "--action", "lefft"],
     "--action 'lefft': no such action (the spec's: left, down, right, up); did you mean left?"),
    ("war", ["--episode", "0", "--at", "1", "--action", "right"], "--action right: masked at step 1 of episode 0"),
    ("gridwar", ["--episode", "0", "--at", "1", "--action", "up"], "a RuleSim run: whatif rebuilds"),
])
def test_a_user_error_is_one_line_and_writes_nothing(world: str, flags: list[str], message: str,
                                                    origins: dict[str, Path], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    origin = ROOT / "tests" / "data" / "rulesim" / "base" if world == "gridwar" else origins[world]
    out = tmp_path / "branch"
    assert main(["whatif", str(origin), *flags, "--run", str(out)]) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("tracelab: error: ") and message in err, err
    assert not out.exists()


def test_a_training_runs_traced_evaluation_game_branches_and_a_policy_plays_on(tmp_path: Path,
                                                                               capsys: pytest.CaptureFixture) -> None:
    """train --env's traced evaluation games are each reset with their own seed; --policy's greedy actions
    play on after the branch (recorded as decisions)."""
    run = tmp_path / "train"
    assert main(["train", "--env", "tracelab/FrozenLake-v1", "--total-timesteps", "400", "--num-envs", "2",
                 "--learning-starts", "100", "--eval-every", "200", "--eval-games", "2", "--trace-eval-games", "2",
                 "--run", str(run)]) == 0
    episode = rows(run, "SELECT max(episode) FROM episodes WHERE kind = 'eval' AND steps >= 2")[0][0]
    names = action_names(run, episode)
    same = branch(run, tmp_path / "same", episode, 1, names[0])
    assert steps_of(same, 0) == steps_of(run, episode) and changes_of(same, 0) == changes_of(run, episode)
    played = branch(run, tmp_path / "policy", episode, 1, names[0], "--policy", str(run / "policy"))
    decided = rows(played, "SELECT min(step), count(*) FROM decisions")[0]
    assert decided == (2, len(steps_of(played, 0)) - 1)   # the policy decided every step after the branch
    capsys.readouterr()
    assert main(["whatif", str(run), "--episode", "0", "--at", "1", "--action", "left",
                 "--run", str(tmp_path / "no")]) == 1
    assert "episode 0 records no steps (only traced games keep theirs" in capsys.readouterr().err


def test_a_gridwar_trainers_policy_plays_on_a_branch_of_a_scenario_game(origins: dict[str, Path], tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """An old policy (GridWar's trainer, RUN/policy of a RuleSim run) loads for whatif on a play --scenario
    run and plays the branch on greedily: its actions after `at` are its greedy choices."""
    policy = ROOT / "tests" / "data" / "rulesim" / "base-policy"
    run = branch(origins["war"], tmp_path / "b", 0, 1, "nothing", "--policy", str(policy))
    capsys.readouterr()
    played = rows(run, "SELECT count(*) FROM raw.decisions WHERE list_position(values, list_max(values)) - 1 = action")
    assert played[0][0] > 0 and played == rows(run, "SELECT count(*) FROM raw.decisions")
