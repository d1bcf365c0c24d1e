"""train --env checkpoints, --resume and traced evaluation games (issue 26 item 2: "DQN with every flag of
today"): real short trainings on slippery FrozenLake, where the worlds' slips make a resume that does not
bring the games back exactly show."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tracelab.cli import main
from tracelab.commands.train import train_env_into
from tracelab.envs.declared.env_source import EnvSource
from tracelab.store.meta import current_meta
from tracelab.train.env_checkpoint import checkpoint_path
from tracelab.train.config import TrainConfig
from tracelab.train.metric_log import WALL_CLOCK_METRICS
from tracelab.viewers.tui.eval_games import eval_games, neighbour
from tracelab.viewers.tui.source import RunSource

from train_helpers import ctrl_c_once_training, run_rows

LAKE = "tracelab/FrozenLake-v1"
SETTINGS = dict(steps=3000, envs=4, warmup=200, target_every=200, eval_every=1000, eval_games=6, eval_envs=4,
                trace_eval_games=2, log_every=250, checkpoint_every=1000, reward_scale=1.0, buffer=5000,
                batch=32, seed=3)
ENCODING = "Discrete(16) one-hot"
RATES = WALL_CLOCK_METRICS  # differ between any two runs
TIMEOUT = 300


def _curves(run: Path) -> list[tuple]:
    return run_rows(run, f"SELECT name, step, value FROM metrics WHERE name NOT IN {RATES} AND name != 'resumed' "
                      f"ORDER BY name, step")


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(one run trained straight through, one stopped at step 1,236 as Ctrl-C would, then resumed in the
    same run through the command line): same config, same seed."""
    d = tmp_path_factory.mktemp("envresume")
    straight, stopped = d / "straight", d / "stopped"
    assert train_env_into(TrainConfig(**SETTINGS), EnvSource(LAKE), straight, ENCODING) == 0
    assert train_env_into(TrainConfig(**SETTINGS), EnvSource(LAKE), stopped, ENCODING, stop_at=1234) == 130
    assert current_meta(stopped)["status"] == "interrupted" and checkpoint_path(stopped).is_file()
    assert main(["train", "--resume", str(stopped), "--env", LAKE]) == 0
    return straight, stopped


def test_a_resumed_run_continues_exactly_as_one_trained_straight_through(runs: tuple[Path, Path]) -> None:
    straight, stopped = runs
    # the losses, ε, Q-values, returns and evaluations at every logged step: the learner, the replay buffer,
    # the generators and the slipping worlds came back as they were at step 1,236
    assert _curves(stopped) == _curves(straight)
    assert run_rows(stopped, "SELECT step, value FROM metrics WHERE name = 'resumed'") == [(1236, 1.0)]
    meta = current_meta(stopped)
    assert meta["status"] == "finished" and meta["resumes"][0]["after"] == "interrupted"
    # the games under way at the stop ended 'aborted' and go on under new ids naming the one each continues
    # (a world whose game had just begun starts a new one, as GridWar's do: EpisodeLog.renumber)
    continued = run_rows(stopped, "SELECT CAST(json_extract(begin_info, '$.continues') AS INT) FROM episodes "
                               "WHERE json_extract(begin_info, '$.continues') IS NOT NULL ORDER BY episode")
    under_way = run_rows(stopped, "SELECT episode FROM episodes WHERE outcome = 'aborted' AND steps > 0 "
                                  "AND train_step < 1236 ORDER BY episode")
    assert continued and sorted(continued) == under_way
    assert run_rows(stopped, "SELECT count(*) = count(DISTINCT episode) FROM episodes") == [(True,)]


def test_evaluation_games_are_traced_so_why_and_the_tui_reach_them(runs: tuple[Path, Path],
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    _, stopped = runs
    games = eval_games(RunSource(stopped))  # what the TUI's ] and [ step through
    assert [(g.train_step, g.eval_round) for g in games] == [(s, r) for r, s in enumerate((1000, 2000, 3000))
                                                              for _ in range(2)]
    assert neighbour(games, games[0].episode, forward=True) == games[1]
    assert current_meta(stopped)["config"]["declared_board"]["rows"][0] == "SFFF"  # the board the TUI draws
    episode = games[-1].episode
    atom, t = run_rows(stopped, f"SELECT atom, t FROM changes WHERE episode = {episode} ORDER BY seq DESC LIMIT 1")[0]
    capsys.readouterr()
    assert main(["why", str(stopped), atom, "-e", str(episode), "--at", str(t)]) == 0
    assert capsys.readouterr().out.startswith(f"{atom} = ")


def test_the_tui_steps_through_the_evaluation_games_with_the_bracket_keys(runs: tuple[Path, Path]) -> None:
    from typing import Any

    from tracelab.viewers.tui.trace import TracePane
    from tui_helpers import episodes_ready, loaded, run_app, wait_for
    _, stopped = runs
    evals = [g.episode for g in eval_games(RunSource(stopped))]

    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("enter")
        pane = app.screen.query_one(TracePane)
        await wait_for(pilot, lambda: pane.filter is not None and loaded(pane.table))
        for episode in evals[:3]:  # each press opens the next evaluation game's trace
            await pilot.press("right_square_bracket")
            await wait_for(pilot, lambda e=episode: pane.filter.episode == e and loaded(pane.table)
                           and pane.table.count > 0)
        await pilot.press("left_square_bracket")
        await wait_for(pilot, lambda: pane.filter.episode == evals[1] and loaded(pane.table))
    run_app([stopped], body, size=(120, 34))


def _one_line(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    capsys.readouterr()
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("tracelab: error: "), err
    return err[0]


def test_resume_mistakes_are_one_line_and_change_nothing(runs: tuple[Path, Path],
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    _, stopped = runs
    before = run_rows(stopped, "SELECT count(*) FROM metrics")
    assert f"--resume {stopped} --env {LAKE}" in _one_line(["train", "--resume", str(stopped)], capsys)
    assert f"trained on --env {LAKE}, not tracelab/Taxi-v4" in \
        _one_line(["train", "--resume", str(stopped), "--env", "tracelab/Taxi-v4"], capsys)
    done = _one_line(["train", "--resume", str(stopped), "--env", LAKE], capsys)
    assert "nothing to resume" in done and f"--resume {stopped} --env {LAKE} --total-timesteps N" in done
    assert "drop --learning-rate" in _one_line(["train", "--resume", str(stopped), "--env", LAKE,
                                                "--learning-rate", "0.1"], capsys)
    assert run_rows(stopped, "SELECT count(*) FROM metrics") == before


def test_run_new_branches_and_raises_the_budget(runs: tuple[Path, Path], tmp_path: Path) -> None:
    _, stopped = runs
    branch = tmp_path / "branch"
    assert main(["train", "--resume", str(stopped), "--env", LAKE, "--run", str(branch),
                 "--total-timesteps", "3500"]) == 0
    assert run_rows(branch, "SELECT max(step) FROM metrics") == [(3500,)]
    assert current_meta(branch)["config"]["resumed_from"] == {"run": str(stopped), "step": 3000}
    assert (branch / "policy-best" / "policy.json").is_file()
    assert run_rows(stopped, "SELECT max(step) FROM metrics") == [(3000,)]  # the run it came from is unchanged


def test_ctrl_c_once_stops_with_a_checkpoint_that_resumes(tmp_path: Path) -> None:
    run = tmp_path / "run"
    status, out, err = ctrl_c_once_training(["train", "--env", LAKE, "--total-timesteps", "100000000",
                                             "--log-every", "100", "--eval-every", "0", "--learning-starts", "100",
                                             "--num-envs", "4", "--run", str(run)], run)
    assert status == 130, err
    assert "writing a checkpoint" in err and f"tracelab train --resume {run} --env {LAKE}" in out
    assert current_meta(run)["status"] == "interrupted"
    logged = run_rows(run, "SELECT max(step) FROM metrics")[0][0]
    resumed = subprocess.run([sys.executable, "-m", "tracelab.cli", "train", "--resume", str(run), "--env", LAKE,
                              "--total-timesteps", str(logged + 400)], capture_output=True, text=True,
                             timeout=TIMEOUT)
    assert resumed.returncode == 0, resumed.stderr
    assert run_rows(run, "SELECT max(step) FROM metrics") == [(logged + 400,)]
    assert run_rows(run, "SELECT count(*) FROM episodes WHERE NOT ended") == [(0,)]


def test_play_env_plays_a_trained_policy_traced(runs: tuple[Path, Path], tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    import numpy as np

    from tracelab.train.env_policy import load_env_policy
    _, stopped = runs
    played = tmp_path / "played"
    assert main(["play", "--env", LAKE, "--policy", str(stopped / "policy"), "--episodes", "4", "--seed", "5",
                 "--run", str(played)]) == 0
    assert current_meta(played)["config"]["policy"] == str(stopped / "policy")
    policy, _ = load_env_policy(stopped / "policy", EnvSource(LAKE))
    for (episode,) in run_rows(played, "SELECT episode FROM episodes ORDER BY episode"):
        rows = run_rows(played, f"SELECT action, obs[1] FROM steps WHERE episode = {episode} ORDER BY step")
        seen = [0] + [int(obs) for _, obs in rows[:-1]]  # each action was chosen from the cell before it
        assert [a for a, _ in rows] == policy.act(np.array(seen)).tolist()  # the policy's, not random
    assert "trained on --env tracelab/FrozenLake-v1, not tracelab/FrozenLake-v1 --env-arg is_slippery=false" in \
        _one_line(["play", "--env", LAKE, "--env-arg", "is_slippery=false", "--policy", str(stopped / "policy"),
                   "--run", str(tmp_path / "other")], capsys)
    assert not (tmp_path / "other").exists()
