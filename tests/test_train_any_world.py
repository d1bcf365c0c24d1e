"""`train --env SPEC` has what GridWar's training has (issue 38, item 3): the method's evaluation counting
where the world declares how a game ends (wins, losses, draws, truncated, eval/method_win_rate), the best
policy kept by the method's win rate, traced evaluation games; the worlds step in the spec's own batched
vector env (DeclaredVectorEnv), falling back to SyncVectorEnv in one note where the spec does not allow it;
its checkpoints replay the worlds' actions, and an older env checkpoint is refused in one line."""
from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from test_spec_world_game import RULES, SPEC, rows

from tracelab.cli import main
from tracelab.envs import make_vec_env
from tracelab.envs.declared.env_source import EnvSource
from tracelab.train.env_checkpoint import checkpoint_path

TINY = ["--total-timesteps", "200", "--learning-starts", "20", "--eval-every", "100", "--eval-games", "12",
        "--trace-eval-games", "2", "--num-envs", "4", "--seed", "5"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, str]:
    """(the world's folder, a run trained on it, what train wrote to stderr)."""
    folder = tmp_path_factory.mktemp("trapworld")
    (folder / "trap.rules").write_text(RULES)
    (folder / "trap.toml").write_text(SPEC)
    run = folder / "run"
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["train", "--env", str(folder / "trap.toml"), *TINY, "--run", str(run)]) == 0
    return folder, run, err.getvalue()


def test_the_worlds_step_in_the_specs_own_vector_env(trained: tuple[Path, Path, str]) -> None:
    _, _, stderr = trained
    assert "4 worlds in DeclaredVectorEnv" in stderr and "note:" not in stderr


def test_every_evaluation_counts_wins_losses_draws_and_the_methods_win_rate(trained: tuple[Path, Path, str]) -> None:
    _, run, _ = trained
    metrics: dict[int, dict[str, float]] = {}
    for name, step, value in rows(run, "SELECT name, step, value FROM metrics WHERE name LIKE 'eval/%'"):
        metrics.setdefault(step, {})[name] = value
    assert sorted(metrics) == [100, 200]
    for m in metrics.values():
        assert m["eval/games"] == 12
        assert m["eval/wins"] + m["eval/losses"] + m["eval/draws"] + m["eval/truncated"] == 12
        assert m["eval/win_rate"] == m["eval/method_win_rate"] == m["eval/wins"] / 12
        if m["eval/wins"]:
            assert m["eval/actions_per_win"] >= 1
    # the traced evaluation games are in the run with the world's outcomes
    traced = rows(run, "SELECT outcome FROM episodes WHERE kind = 'eval'")
    assert len(traced) == 4 and {o for (o,) in traced} <= {"win", "loss", "truncated"}


def test_the_best_policy_is_kept_by_the_methods_win_rate(trained: tuple[Path, Path, str]) -> None:
    _, run, _ = trained
    best = json.loads((run / "policy-best" / "policy.json").read_text())
    selected = best["trained"]["selected_by"]
    assert selected["metric"] == "eval/method_win_rate"
    rates = dict(rows(run, "SELECT step, value FROM metrics WHERE name = 'eval/method_win_rate'"))
    assert selected["value"] == max(rates.values())
    assert best["trained"]["step"] == min(s for s, v in rates.items() if v == selected["value"])


def test_eval_env_counts_the_outcomes(trained: tuple[Path, Path, str], capsys: pytest.CaptureFixture) -> None:
    folder, run, _ = trained
    capsys.readouterr()
    assert main(["eval", str(run / "policy"), "--env", str(folder / "trap.toml"), "--games", "10", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["wins"] + out["losses"] + out["draws"] + out["truncated"] == 10
    assert out["method_win_rate"] == out["win_rate"] and len(out["win_rate_ci95"]) == 2
    assert main(["eval", str(run / "policy"), "--env", str(folder / "trap.toml"), "--games", "10"]) == 0
    assert "outcomes" in capsys.readouterr().out


def test_an_older_env_checkpoint_is_refused_in_one_line(trained: tuple[Path, Path, str], tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    folder, run, _ = trained
    state = torch.load(checkpoint_path(run), weights_only=True)
    state["format"] = "tracelab-dqn-env-checkpoint/1"
    old = tmp_path / "old"
    (old / "checkpoint").mkdir(parents=True)
    torch.save(state, old / "checkpoint" / "checkpoint.pt")
    capsys.readouterr()
    assert main(["train", "--resume", str(old), "--env", str(folder / "trap.toml"), "--run",
                 str(tmp_path / "new")]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("tracelab: error:") and "earlier tracelab" in err[0]
    assert not (tmp_path / "new").exists()


def test_a_spec_the_vector_env_does_not_play_falls_back_saying_so() -> None:
    from gymnasium.vector import SyncVectorEnv

    from tracelab.train.env_policy import make_vector_env
    env, note = make_vector_env(EnvSource("tracelab/Taxi-v4", {"fickle_passenger": True}), 2)
    try:
        assert isinstance(env, SyncVectorEnv) and "SyncVectorEnv" in note and "after" in note
    finally:
        env.close()
    env, note = make_vector_env(EnvSource("tracelab/Taxi-v4", {}), 2)
    assert type(env).__name__ == "DeclaredVectorEnv" and note is None and env.max_episode_steps == 200
    env.close()


def test_the_vector_env_restarts_only_the_worlds_a_reset_mask_names(trained: tuple[Path, Path, str]) -> None:
    folder, _, _ = trained
    env = make_vec_env(folder / "trap.toml", 3)
    env.reset(seed=1)
    env.step(np.array([1, 1, 1]))
    _, info = env.reset(options={"reset_mask": np.array([False, True, False])})
    assert info["t"].tolist() == [1, 0, 1]
