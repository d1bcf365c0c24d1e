"""Stable-Baselines3 trainings logged into a tracelab run (tracelab/train/sb3.py): a short real PPO training
on a rules-declared env and on GridWar base, read back through tracelab's store and CLI."""
from __future__ import annotations

import runpy
import sys
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("stable_baselines3")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback, CallbackList  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402

from patience import wait_until  # noqa: E402

import tracelab.envs  # noqa: E402,F401  (registers the GridWar and toy-text ids)
from tracelab.cli import main  # noqa: E402
from tracelab.errors import UserError  # noqa: E402
from tracelab.store.meta import current_meta  # noqa: E402
from tracelab.store.reader import open_run  # noqa: E402
from tracelab.train.sb3 import MODEL_FILE, TracelabCallback  # noqa: E402

FROZEN = "tracelab/FrozenLake-v1"
GRIDWAR = "tracelab/GridWar-base-v0"
STEPS, ENVS = 1024, 4


def _ppo(env_id: str, **kwargs: object) -> PPO:
    torch.set_num_threads(1)
    env = make_vec_env(env_id, n_envs=ENVS, seed=0, env_kwargs=kwargs or None)
    return PPO("MlpPolicy", env, n_steps=64, batch_size=64, n_epochs=2, seed=0, device="cpu")


def _train(run: Path, env_id: str, **kwargs: object) -> TracelabCallback:
    model = _ppo(env_id, **kwargs)
    with TracelabCallback(run, env_id, kwargs, eval_every=512, eval_games=6, trace_eval_games=2,
                          eval_envs=4) as cb:
        model.learn(STEPS, callback=cb)
    return cb


@pytest.fixture(scope="module")
def frozen_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run = tmp_path_factory.mktemp("sb3") / "ppo-frozen"
    _train(run, FROZEN, is_slippery=False)
    return run


@pytest.fixture(scope="module")
def gridwar_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run = tmp_path_factory.mktemp("sb3") / "ppo-base"
    _train(run, GRIDWAR)
    return run


def _rows(run: Path, sql: str) -> list[tuple]:
    con = open_run(run)
    try:
        return con.execute(sql).fetchall()
    finally:
        con.close()


def _check_training_rows(run: Path) -> None:
    """What every SB3 run holds: SB3's logger values and train_return as metrics at the training steps,
    every training episode (their steps add up to the training's), status finished, the model file."""
    names = {n for (n,) in _rows(run, "SELECT DISTINCT name FROM metrics")}
    assert {"rollout/ep_rew_mean", "train/loss", "time/fps", "train_return"} <= names
    assert _rows(run, "SELECT max(step) FROM metrics") == [(STEPS,)]
    assert _rows(run, "SELECT sum(steps) FROM episodes WHERE kind = 'train'") == [(STEPS,)]
    assert _rows(run, "SELECT count(*) FROM episodes WHERE kind = 'train' AND outcome = 'aborted'") == [(ENVS,)]
    assert current_meta(run)["status"] == "finished"
    assert (run / MODEL_FILE).is_file()


def _eval_games(run: Path) -> list[tuple[int, int, int]]:
    """(episode, train_step, eval_round) of the traced evaluation games, each with change rows."""
    return _rows(run, "SELECT e.episode, e.train_step, CAST(json_extract(e.begin_info, '$.eval_round') AS INT) "
                      "FROM episodes e WHERE kind = 'eval' AND EXISTS (SELECT 1 FROM changes c WHERE "
                      "c.episode = e.episode) ORDER BY episode")


def _why_answers(run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`tracelab why` explains the last change of the first traced evaluation game."""
    episode = _eval_games(run)[0][0]
    atom, t = _rows(run, f"SELECT atom, t FROM changes WHERE episode = {episode} ORDER BY seq DESC LIMIT 1")[0]
    capsys.readouterr()
    assert main(["why", str(run), atom, "-e", str(episode), "--at", str(t)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{atom} = ") and "set at t=" in out


def test_ppo_on_a_declared_env_logs_metrics_episodes_and_traced_evaluations(
        frozen_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _check_training_rows(frozen_run)
    # evaluations at 512 and at the end, two traced games each, ids after the training episodes begun then
    assert [(s, r) for _, s, r in _eval_games(frozen_run)] == [(512, 0), (512, 0), (1024, 1), (1024, 1)]
    assert {n for (n,) in _rows(frozen_run, "SELECT name FROM metrics WHERE step = 1024 AND name LIKE 'eval/%'")} \
        >= {"eval/mean_return", "eval/success_rate", "eval/games"}
    assert _rows(frozen_run, "SELECT value FROM metrics WHERE name = 'eval/games' AND step = 512") == [(6.0,)]
    config = current_meta(frozen_run)["config"]
    assert config["env"] == {"name": FROZEN, "kwargs": {"is_slippery": False}}
    assert config["declared_board"]["rows"][0] == "SFFF"  # the TUI draws the board from it
    assert config["learner"]["algorithm"] == "PPO" and config["learner"]["n_steps"] == 64
    _why_answers(frozen_run, capsys)


def test_ppo_on_gridwar_base_logs_win_rates_and_traced_games_that_why_explains(
        gridwar_run: Path, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    _check_training_rows(gridwar_run)
    assert len(_eval_games(gridwar_run)) == 4
    assert _rows(gridwar_run, "SELECT count(*) FROM metrics WHERE name = 'eval/win_rate'") == [(2,)]
    outcomes = {o for (o,) in _rows(gridwar_run, "SELECT DISTINCT outcome FROM episodes WHERE kind = 'train'")}
    assert outcomes <= {"win", "loss", "draw", "truncated", "aborted"} and outcomes & {"win", "loss", "draw"}
    meta = current_meta(gridwar_run)
    assert meta["scenario"] == "GridWar-base-v0"  # the declared env over war.toml: its board from the spec
    assert meta["config"]["declared_board"]["rows"][-1] == ".......r"
    _why_answers(gridwar_run, capsys)
    out = tmp_path / "replay.rrd"
    episode = _eval_games(gridwar_run)[0][0]
    assert main(["replay", str(gridwar_run), "--episode", str(episode), "--save", str(out)]) == 0
    assert out.stat().st_size > 0


class _StopAt(BaseCallback):
    def __init__(self, step: int) -> None:
        super().__init__()
        self.step = step

    def _on_step(self) -> bool:
        return self.num_timesteps < self.step


class _Peek(BaseCallback):
    """Reads the run while SB3 trains (from step 512: after the first rollout's dump): its status and the
    metric rows another process would see by then (the writer publishes within a second)."""
    def __init__(self, run: Path) -> None:
        super().__init__()
        self.run, self.seen = run, None

    def _on_step(self) -> bool:
        if self.seen is None and self.num_timesteps >= 512:
            wait_until(lambda: _rows(self.run, "SELECT count(*) FROM metrics")[0][0] > 0,
                       "the first rollout's metrics visible while SB3 trains")
            self.seen = (current_meta(self.run)["status"], _rows(self.run, "SELECT count(*) FROM metrics")[0][0])
        return True


def test_the_run_is_read_live_and_a_training_stopped_early_is_interrupted(tmp_path: Path) -> None:
    run = tmp_path / "stopped"
    stopped, peek = TracelabCallback(run, FROZEN, eval_every=0, eval_games=2, trace_eval_games=1), _Peek(run)
    _ppo(FROZEN).learn(STEPS, callback=CallbackList([stopped, peek, _StopAt(768)]))
    assert peek.seen is not None and peek.seen[0] == "running" and peek.seen[1] > 0
    assert current_meta(run)["status"] == "interrupted"
    # stopped early: no final evaluation, the episodes so far
    assert _rows(run, "SELECT count(*) FROM metrics WHERE name LIKE 'eval/%'") == [(0,)]
    assert _rows(run, "SELECT sum(steps) FROM episodes") == [(768,)]


@pytest.mark.parametrize("error, status", [(RuntimeError, "failed"), (KeyboardInterrupt, "interrupted")])
def test_a_training_that_raises_inside_the_with_is_failed_or_interrupted(
        tmp_path: Path, error: type[BaseException], status: str) -> None:
    class Boom(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps >= 128:
                raise error("boom")
            return True
    with pytest.raises(error, match="boom"):
        with TracelabCallback(tmp_path / "run", FROZEN, eval_every=0) as cb:
            _ppo(FROZEN).learn(STEPS, callback=CallbackList([cb, Boom()]))
    assert current_meta(tmp_path / "run")["status"] == status
    assert _rows(tmp_path / "run", "SELECT count(*) FROM episodes WHERE NOT ended") == [(0,)]


def test_an_env_whose_games_cannot_be_traced_is_refused_in_one_line(tmp_path: Path) -> None:
    cb = TracelabCallback(tmp_path / "run", "CartPole-v1")
    with pytest.raises(UserError, match="'CartPole-v1': not a rules-declared env .* cannot trace its games"):
        _ppo("CartPole-v1").learn(64, callback=cb)
    assert not (tmp_path / "run").exists()


def test_logging_and_evaluating_leave_the_training_as_it_would_be_without(tmp_path: Path) -> None:
    """The evaluations play in their own envs with greedy actions: the trained weights are the same bit for
    bit as without the callback (same seed)."""
    plain = _ppo(FROZEN)  # built (seeding torch's and numpy's global generators) and trained, then the other
    plain.learn(512)
    logged = _ppo(FROZEN)
    with TracelabCallback(tmp_path / "run", FROZEN, eval_every=128, eval_games=3, trace_eval_games=1) as cb:
        logged.learn(512, callback=cb)
    assert _rows(tmp_path / "run", "SELECT count(DISTINCT step) FROM metrics WHERE name = 'eval/games'") == [(4,)]
    a, b = plain.policy.state_dict(), logged.policy.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_the_tui_training_view_draws_the_ppo_run_s_curves(gridwar_run: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Its loss plot draws SB3's train/loss, its return plot train_return, its win-rate plot eval/win_rate."""
    monkeypatch.setenv("TEXTUAL_ANIMATIONS", "none")
    from tracelab.viewers.tui.plot import BraillePlot
    from tui_helpers import run_app, wait_for

    async def body(app: Any, pilot: Any) -> None:
        await pilot.press("6")
        await wait_for(pilot, lambda: app.screen.panes["training"].is_attached)
        plots = {p: app.screen.query_one(f"#plot-{p}", BraillePlot) for p in ("loss", "return", "win-rate")}
        await wait_for(pilot, lambda: all(plot.points > 0 for plot in plots.values()))
        assert [s.name for s in plots["loss"].series] == ["train/loss"]
        assert "train_return" in [s.name for s in plots["return"].series]
        assert "eval/win_rate" in [s.name for s in plots["win-rate"].series]
    run_app([gridwar_run], body, size=(100, 30))


def _greedy_decisions(run: Path, output: str) -> list[tuple]:
    """Every traced evaluation step has a decision with the model's output for every action, and the
    greedy action is its argmax (issue 39)."""
    steps = _rows(run, "SELECT s.episode, s.step, s.agent, s.action_name FROM steps s JOIN episodes e USING (episode) "
                       "WHERE e.kind = 'eval' AND s.agent NOT LIKE 'blue%' ORDER BY ALL")
    rows = _rows(run, "SELECT episode, step, agent, action_name, output, actions, \"values\", state_value "
                      "FROM decisions ORDER BY episode, step, agent")
    assert steps and [r[:4] for r in rows] == steps
    for *_, name, kind, actions, values, state_value in rows:
        assert kind == output and len(values) == len(actions) and actions[int(np.argmax(values))] == name
        assert (state_value is not None) == (output == "logits")
    return rows


def test_ppo_traced_evaluations_record_the_logits_and_state_value(frozen_run: Path, gridwar_run: Path) -> None:
    assert len(_greedy_decisions(frozen_run, "logits")[0][5]) == 4
    _greedy_decisions(gridwar_run, "logits")


def test_dqn_traced_evaluations_record_the_q_values(tmp_path: Path) -> None:
    from stable_baselines3 import DQN
    torch.set_num_threads(1)
    model = DQN("MlpPolicy", make_vec_env(FROZEN, n_envs=1, seed=0), learning_starts=0, buffer_size=1000, seed=0,
                device="cpu")
    run = tmp_path / "dqn"
    with TracelabCallback(run, FROZEN, eval_every=0, eval_games=2, trace_eval_games=2, eval_envs=1) as cb:
        model.learn(64, callback=cb)
    _greedy_decisions(run, "q")


def test_ppo_takes_a_spec_file_as_the_docs_and_the_example_say(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/training.md's `make_vec_env(spec file)` and `examples/sb3_ppo.py --env my.toml` (SB3's own
    make_vec_env takes ids only: a path was a `Malformed environment ID`)."""
    from test_spec_world_game import RULES, SPEC

    from tracelab.train.sb3 import make_vec_env as tracelab_vec_env
    (tmp_path / "trap.rules").write_text(RULES)
    spec = tmp_path / "trap.toml"
    spec.write_text(SPEC)
    torch.set_num_threads(1)
    model = PPO("MlpPolicy", tracelab_vec_env(str(spec), n_envs=2, seed=0, env_kwargs={"door_reward": 2.0}),
                n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
    with TracelabCallback(tmp_path / "ppo", str(spec), {"door_reward": 2.0}, eval_every=0, eval_games=4,
                          trace_eval_games=1, eval_envs=2) as cb:
        model.learn(128, callback=cb)
    assert _rows(tmp_path / "ppo", "SELECT DISTINCT outcome FROM episodes WHERE kind = 'eval' AND outcome <> "
                                   "'aborted'")[0][0] in ("win", "loss", "truncated")
    assert current_meta(tmp_path / "ppo")["config"]["env"]["kwargs"] == {"door_reward": 2.0}
    example = Path(__file__).resolve().parent.parent / "examples" / "sb3_ppo.py"
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", [str(example), "--env", "trap.toml", "--steps", "128", "--n-envs", "2",
                                      "--n-steps", "64", "--eval-every", "0", "--eval-games", "2", "--run", "runs/ex"])
    runpy.run_path(str(example), run_name="__main__")
    assert current_meta(tmp_path / "runs" / "ex")["status"] == "finished"
