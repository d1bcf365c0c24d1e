"""train --env / eval --env on declared worlds (issue 26), and value iteration over the rules' own
transitions checked against gymnasium's FrozenLake table."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from tracelab import RULES_DIR
from tracelab.cli import main
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.toytext import spec_path
from tracelab.envs.declared.env_source import EnvSource, parse_env_args
from tracelab.store import run_info
from tracelab.train.env_source import ObservationEncoder
from tracelab.train.tabular import enumerate_transitions, optimal_start_value, value_iteration

TIMEOUT = 600  # a command that hangs fails the test instead


def tracelab(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "tracelab.cli", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=TIMEOUT)


@pytest.fixture(scope="module")
def dry_lake_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real, tiny training run on the 4x4 lake without slipping (seconds)."""
    d = tmp_path_factory.mktemp("envtrain")
    p = tracelab("train", "--env", "tracelab/FrozenLake-v1", "--env-arg", "is_slippery=false",
                 "--total-timesteps", "3000", "--num-envs", "4", "--learning-starts", "200",
                 "--target-network-frequency", "200", "--eval-every", "1000", "--eval-games", "10",
                 "--run", str(d / "run"), cwd=d)
    assert p.returncode == 0, p.stderr
    assert "Discrete(16) one-hot" in p.stderr
    # an env keeps its own rewards (about 1): train's default scale (0.01) is for GridWar's hundreds
    assert "reward scale 1 (the method's)" in p.stderr
    return d / "run"


def test_train_env_learns_the_six_step_path_and_eval_env_plays_it(dry_lake_run: Path) -> None:
    policy = json.loads((dry_lake_run / "policy" / "policy.json").read_text())
    assert policy["env"] == {"name": "tracelab/FrozenLake-v1", "kwargs": {"is_slippery": False}}
    assert policy["network"]["inputs"] == 16 and policy["network"]["outputs"] == 4
    p = tracelab("eval", str(dry_lake_run / "policy"), "--env", "tracelab/FrozenLake-v1", "--env-arg",
                 "is_slippery=false", "--games", "20", "--json", cwd=dry_lake_run.parent)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["games"] == 20 and out["success_rate"] == 1.0 and out["mean_return"] == 1.0
    assert out["mean_steps"] == 6.0  # the shortest path from S to G on the 4x4 map


def test_the_run_logs_evaluations_and_episodes(dry_lake_run: Path) -> None:
    from tracelab.store.reader import open_run
    con = open_run(dry_lake_run)
    rows = con.sql("SELECT step, value FROM metrics WHERE name = 'eval/success_rate' ORDER BY step").fetchall()
    ended = con.sql("SELECT count(*) FROM episodes WHERE outcome = 'terminated'").fetchall()[0][0]
    con.close()
    assert [r[0] for r in rows] == [1000, 2000, 3000] and rows[-1][1] == 1.0
    assert ended > 0


def _one_line_error(p: subprocess.CompletedProcess, text: str) -> None:
    assert p.returncode == 1
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tracelab: error: ") and text in lines[0], p.stderr


def test_eval_env_refuses_another_env_in_one_line(dry_lake_run: Path) -> None:
    pol = str(dry_lake_run / "policy")
    cwd = dry_lake_run.parent
    _one_line_error(tracelab("eval", pol, "--env", "tracelab/FrozenLake-v1", cwd=cwd),
                    "trained on --env tracelab/FrozenLake-v1 --env-arg is_slippery=false, not "
                    "tracelab/FrozenLake-v1")
    _one_line_error(tracelab("eval", pol, "--env", "tracelab/Taxi-v4", cwd=cwd), "not tracelab/Taxi-v4")
    # without --env: the tracelab id it was trained on, as trained
    played = tracelab("eval", pol, "--games", "2", cwd=cwd)
    assert played.returncode == 0 and "on tracelab/FrozenLake-v1 --env-arg is_slippery=false" in played.stdout
    _one_line_error(tracelab("train", "--resume", str(dry_lake_run), cwd=cwd),
                    f"tracelab train --resume {dry_lake_run} --env tracelab/FrozenLake-v1 --env-arg is_slippery=false")


@pytest.mark.parametrize("args, text", [
    (["--env", "tracelab/FrozenLake-v1", "--scenario", "advanced"], "--scenario describes GridWar"),
    (["--env", "nope-v0"], "neither a registered env id"),
    (["--env", "tracelab/FrozenLake-v1", "--env-arg", "bogus=1"], "unknown keyword argument 'bogus'"),
    (["--env", "tracelab/FrozenLake-v1", "--env-arg", "is_slippery"], "expected key=value"),
    (["--env-arg", "is_slippery=false"], "--env-arg needs --env"),
    (["--env", "tracelab/FrozenLake-v1", "--resume", "runs/x"], "runs/x: not a training run's directory"),
])
def test_train_env_mistakes_are_one_line(args: list[str], text: str, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["train", *args, "--run", str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and text in err[0], err
    assert not (tmp_path / "r").exists()


def test_a_spec_world_trains_with_the_kernel_and_scripted_exploration_flags(tmp_path: Path) -> None:
    """--kernel and --explore-scripted (the spec's `[agents] script`) are any spec world's, not GridWar's alone."""
    run = tmp_path / "r"
    assert main(["train", "--env", str(RULES_DIR / "gridworld" / "war.toml"), "--kernel", "counting",
                 "--explore-scripted", "0.5", "--total-timesteps", "64", "--num-envs", "2", "--learning-starts", "32",
                 "--batch-size", "16", "--eval-every", "0", "--eval-games", "2", "--eval-envs", "2",
                 "--trace-eval-games", "0", "--log-every", "32", "--run", str(run)]) == 0
    config = run_info(run).meta["config"]
    assert (config["kernel"], config["explore_scripted"]) == ("counting", 0.5)


def test_env_args_are_read_as_toml_values() -> None:
    assert parse_env_args(["is_slippery=false", "success_rate=0.5", "map_name=8x8",
                           'desc=["SF", "HG"]']) == \
        {"is_slippery": False, "success_rate": 0.5, "map_name": "8x8", "desc": ["SF", "HG"]}
    assert EnvSource("x", {"is_slippery": False}).describe() == "x --env-arg is_slippery=false"


def test_a_discrete_observation_is_one_hot() -> None:
    enc = ObservationEncoder(gym.spaces.Discrete(16), "x")
    out = enc(np.array([5, 0]))
    assert out.shape == (2, 16) and out[0, 5] == 1.0 and out[1, 0] == 1.0 and out.sum() == 2.0
    multi = ObservationEncoder(gym.spaces.MultiDiscrete([3, 2]), "x")
    assert multi(np.array([[2, 1]])).tolist() == [[0, 0, 1, 0, 1]]


def _gymnasium_value(P: dict, n_states: int, n_actions: int, horizon: int) -> np.ndarray:
    """Finite-horizon value iteration over gymnasium's own table (the independent check)."""
    v = np.zeros(n_states)
    for _ in range(horizon):
        v = np.array([max(sum(p * (r + (0.0 if done else v[s2])) for p, s2, r, done in P[s][a])
                          for a in range(n_actions)) for s in range(n_states)])
    return v


def test_value_iteration_over_the_rules_matches_gymnasiums_table_on_slippery_frozenlake() -> None:
    tr = enumerate_transitions(load_spec(spec_path("frozen_lake.toml")))
    ours = optimal_start_value(tr, horizon=100)
    env = gym.make("FrozenLake-v1").unwrapped
    theirs = _gymnasium_value(env.P, 16, 4, 100)[0]
    assert ours == pytest.approx(theirs, abs=1e-12)
    assert ours == pytest.approx(0.7442, abs=5e-4)  # the best success rate within FrozenLake's 100 steps
    assert optimal_start_value(tr, horizon=1000) == pytest.approx(0.8235, abs=5e-4)  # no limit: 14/17


def test_value_iteration_finds_the_cliff_path_and_the_dry_lake_path() -> None:
    cliff = enumerate_transitions(load_spec(spec_path("cliff_walking.toml")))
    assert optimal_start_value(cliff, horizon=100) == pytest.approx(-13.0)
    dry = enumerate_transitions(load_spec(spec_path("frozen_lake.toml"), is_slippery=False))
    v, _ = value_iteration(dry, horizon=6)
    assert v[0] == 1.0 and value_iteration(dry, horizon=5)[0][0] == 0.0  # six steps, no fewer


def test_value_iteration_over_taxis_rules_matches_gymnasiums_table_in_every_state() -> None:
    tr = enumerate_transitions(load_spec(spec_path("taxi.toml")), start_seeds=200)
    ours, _ = value_iteration(tr, horizon=200)
    env = gym.make("Taxi-v4").unwrapped
    theirs = _gymnasium_value(env.P, 500, 6, 200)
    reached = sorted(tr.outcomes)
    assert len(reached) == 400  # the 100 with the passenger at its destination are ends or never reached
    assert np.allclose(ours[reached], theirs[reached], atol=1e-9)


def test_masked_readable_training_on_taxi_keeps_the_masks_in_replay() -> None:
    """--mask reads Taxi's info["action_mask"]: exploration takes allowed actions only and the replay holds
    the next state's mask; --double-dqn trains the readable learner through the same loop."""
    from tracelab.train.config import TrainConfig
    from tracelab.train.env_trainer import EnvTrainer
    from tracelab.train.replay import MASKED_Q
    cfg = TrainConfig(steps=400, envs=4, warmup=100, batch=16, buffer=1000, eval_every=0, eval_games=4,
                      eval_envs=2, log_every=200, mask=True, double_dqn=True, learner="readable")
    tr = EnvTrainer(cfg, EnvSource("tracelab/Taxi-v4"))
    try:
        assert tr.train() == "finished"
        buf = tr.learner.buffer
        assert buf.masked and buf.size == 400 and tr.learner.updates > 0
        penalties = buf.rows[:buf.size, buf._pen:buf._pen + 6]
        assert (penalties == MASKED_Q).any() and (penalties == 0).all(axis=1).sum() < buf.size
        assert tr.last_eval is not None and tr.last_eval.games == 4
    finally:
        tr.close()
