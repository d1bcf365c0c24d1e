"""Several agents a team on the spec path (issue 38 item 2, one trainer): DeclaredVectorEnv's team mode
steps each world as TeamEnv does; EnvTrainer trains every agent with one shared network, an agent's
transition running from its decision to its next one (a slow agent's spans two steps), its death or the
episode's end, as RuleSim's trainer did; `train --scenario` trains 2v2 and the non-Markov scenario, its
evaluations count wins and losses and trace every agent's decision, and its checkpoints resume exactly."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracelab.cli import main
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.play import TeamEnv
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.vector_env import DeclaredVectorEnv
from tracelab.train.config import TrainConfig
from tracelab.train.env_checkpoint import checkpoint_path, load_env_checkpoint, save_env_checkpoint
from tracelab.train.env_trainer import EnvTrainer
from tracelab.train.memory import memory_limit
from tracelab.train.torch_files import load_tensors

from train_helpers import run_rows

NONMARKOV = "tracelab/GridWar-nonmarkov-v0"
WAR = "rules/gridworld/war.toml"
TINY = ["--total-timesteps", "240", "--num-envs", "4", "--learning-starts", "40", "--eval-every", "240",
        "--eval-games", "4", "--eval-envs", "3", "--trace-eval-games", "1", "--log-every", "80",
        "--buffer-size", "600", "--batch-size", "16", "--checkpoint-every", "120"]


def test_each_world_of_the_team_vector_env_steps_as_team_env() -> None:
    """World i of the batch, reset with seed s + i, gives TeamEnv's observations, rewards and ends for the same
    actions (-1: the agent does nothing); the agents' rewards sum to the team's, the slow agent decides on
    even steps only."""
    worlds, seed = 3, 11
    vec = DeclaredVectorEnv("rules/gridworld/war_nonmarkov.toml", worlds)
    singles = [TeamEnv(load_spec("rules/gridworld/war_nonmarkov.toml")) for _ in range(worlds)]
    obs, info = vec.reset(seed=seed)
    for i, env in enumerate(singles):
        one, _ = env.reset(seed=seed + i)
        assert np.array_equal(obs[i], one)
    rng = np.random.default_rng(0)
    for t in range(12):
        assert info["decides"][:, 1].all() == (t % 2 == 0)  # agent 2 is slow: it decides on even steps
        actions = np.where(info["decides"], rng.integers(0, 9, (worlds, 2)), -1)
        obs, reward, term, trunc, info = vec.step(actions)
        assert np.allclose(info["agent_reward"].sum(axis=1), reward)
        for i, env in enumerate(singles):
            one, r, te, tr, _ = env.step(actions[i])
            if term[i] or trunc[i]:  # the batch restarted it: its last observation is final_obs
                assert np.array_equal(info["final_obs"][i], one) and (te, tr) == (term[i], trunc[i])
                env.reset(seed=10_000 + i)
                continue
            assert np.array_equal(obs[i], one) and r == pytest.approx(reward[i])


def _trainer(steps: int, **kw: object) -> EnvTrainer:
    cfg = TrainConfig(steps=steps, envs=4, warmup=40, buffer=4000, batch=16, eval_every=0, log_every=1000,
                      checkpoint_every=0, seed=2, **kw)
    return EnvTrainer(cfg, EnvSource(NONMARKOV))


def test_every_agent_is_a_row_and_a_slow_agent_adds_no_transition_where_it_does_not_decide() -> None:
    """The replay holds both agents' transitions (each row ends in its agent's one-hot index): the fast
    agent's span one step (discount γ), the slow one's two (γ², its move takes two steps), or end without a
    bootstrap (0: the game ended or the agent died); no dead agent ever decides."""
    tr = _trainer(240)
    tr.train()
    buf = tr.learner.buffer
    d = buf.obs_size
    obs, discount = buf.rows[:buf.size, :d], buf.rows[:buf.size, -1]  # a row: [obs, 1, next obs, 1, ...]
    agent = obs[:, -2:].argmax(axis=1)
    gamma = tr.cfg.gamma
    fast, slow = discount[agent == 0], discount[agent == 1]
    assert (np.isclose(fast, 0) | np.isclose(fast, gamma)).all()
    assert (np.isclose(slow, 0) | np.isclose(slow, gamma ** 2)).all() and (slow > 0).any()
    assert 0.4 < len(slow) / len(fast) < 0.6  # one decision every other step
    own_x = np.where(agent == 0, obs[:, 0], obs[:, 2])  # the team's view: red 1's x, y, red 2's x, y, ...
    assert (own_x >= 0).all()  # a dead agent (seen nowhere: -1) made no transition
    tr.close()


def test_slow_every_step_asks_the_slow_agent_every_step() -> None:
    tr = _trainer(160, slow_every_step=True)
    tr.train()
    buf = tr.learner.buffer
    agent = buf.rows[:buf.size, buf.obs_size - 2:buf.obs_size].argmax(axis=1)
    assert 0.8 < (agent == 1).sum() / (agent == 0).sum() < 1.25  # about as often as the fast one (not half)
    tr.close()


def test_train_2v2_counts_wins_traces_every_agent_and_resumes(tmp_path: Path) -> None:
    run = tmp_path / "run"
    argv = ["train", "--scenario", "base", "--agents", "2", "--explore-scripted", "0.5", *TINY]
    assert main([*argv, "--total-timesteps", "120", "--run", str(run)]) == 0
    # the traced evaluation game records each agent's decision; the games count as wins or losses
    agents = {a for (a,) in run_rows(run, "SELECT DISTINCT agent FROM decisions")}
    assert agents == {"red-agent-1", "red-agent-2"}
    outcomes = {o for (o,) in run_rows(run, "SELECT outcome FROM episodes WHERE kind = 'eval'")}
    assert outcomes and outcomes <= {"win", "loss", "truncated"}, outcomes
    names = {n for (n,) in run_rows(run, "SELECT name FROM metrics WHERE name LIKE 'eval/%'")}
    assert {"eval/method_win_rate", "eval/wins", "eval/losses"} <= names, names
    assert main(["train", "--resume", str(run), "--total-timesteps", "240"]) == 0
    assert load_tensors(checkpoint_path(run), 10**9)["step"] == 240


def test_a_team_checkpoint_resumes_exactly_as_one_trained_straight_through(tmp_path: Path) -> None:
    """Stopped at step 120, written and read back as a checkpoint file, then trained on: the learner ends
    where one trained straight through does (the open transitions, the worlds' replay, the streams)."""
    source = EnvSource("tracelab/GridWar-base-v0", {"agents_per_team": 2})
    cfg = TrainConfig(steps=240, envs=4, warmup=40, buffer=600, batch=16, eval_every=0, log_every=80,
                      checkpoint_every=0, seed=1, explore_scripted=0.5)
    straight, stopped = EnvTrainer(cfg, source), EnvTrainer(cfg, source)
    straight.train()
    stopped.train(stop_at=120)
    save_env_checkpoint(stopped, tmp_path)
    state = load_env_checkpoint(tmp_path, source, memory_limit(None, "--max-memory"))
    assert state["pending"]["open"].shape == (4, 2)
    resumed = EnvTrainer(cfg, source)
    resumed.load_state(state)
    resumed.train()
    assert resumed.learner.updates == straight.learner.updates > 0
    assert np.array_equal(resumed.learner.state()["params"], straight.learner.state()["params"])
    for tr in (straight, stopped, resumed):
        tr.close()


def test_the_non_markov_scenario_trains_through_its_spec(tmp_path: Path) -> None:
    run = tmp_path / "run"
    assert main(["train", "--scenario", "nonmarkov", "--non-markov", *TINY, "--run", str(run)]) == 0
    assert run_rows(run, "SELECT count(DISTINCT agent) FROM decisions") == [(2,)]
