"""`tracelab train`: a run logs what the contract says (docs/training.md),
resume equals no interruption, the learner learns a tiny game, Ctrl-C leaves an interrupted run with a
checkpoint."""
from __future__ import annotations

import json
from dataclasses import asdict

import numpy as np
import pytest
import torch

from tracelab.cli import main
from tracelab.store import open_run, run_info
from tracelab.store.why import explain, render_why
from tracelab.train.config import TrainConfig
from tracelab.train.env_checkpoint import checkpoint_path
from tracelab.train.env_policy import load_env_policy
from tracelab.train.metric_log import WALL_CLOCK_METRICS
from tracelab.train.torch_files import load_tensors
from train_helpers import (WALK, WALK_ARGS, ctrl_c_once_training, train_walk, walk_argv, walk_config, walk_source,
                           walk_trainer)

TRAINING_METRICS = {"loss", "epsilon", "q_max_mean", "env_steps_per_s", "updates_per_s", "train_return"}
EVAL_METRICS = {f"eval/{k}" for k in ("games", "wins", "losses", "draws", "truncated", "win_rate", "mean_return",
                                       "method_win_rate")}
TIMING = WALL_CLOCK_METRICS


def _metrics(run) -> dict[tuple[int, str], float]:
    con = open_run(run)
    rows = con.execute("SELECT step, name, value FROM metrics").fetchall()
    con.close()
    return {(s, n): v for s, n, v in rows if n not in TIMING}


def _ended_training_episodes(run) -> list[tuple]:
    con = open_run(run)
    rows = con.execute("SELECT episode, outcome, steps, reward FROM episodes WHERE kind = 'train' "
                       "AND ended AND outcome <> 'aborted' ORDER BY episode").fetchall()
    con.close()
    return rows


def load_checkpoint(run) -> dict:
    return load_tensors(checkpoint_path(run), 10**9)


def test_a_run_logs_metrics_episodes_evaluations_checkpoint_and_policy(tmp_path):
    run = tmp_path / "run"
    cfg = walk_config(steps=400, seed=3)
    assert train_walk(cfg, run) == 0
    info = run_info(run)
    assert info.status == "finished" and info.meta["command"].startswith("tracelab train")
    assert info.meta["config"]["steps"] == 400 and info.meta["config"]["lr"] == 3e-3
    con = open_run(run)
    names = {n for (n,) in con.execute("SELECT DISTINCT name FROM metrics").fetchall()}
    assert TRAINING_METRICS | EVAL_METRICS <= names
    eps = con.execute("SELECT step, value FROM metrics WHERE name = 'epsilon' ORDER BY step").fetchall()
    assert [s for s, _ in eps] == [100, 200, 300, 400] and eps[0][1] == 1.0 and eps[-1][1] == cfg.eps_end
    evals = con.execute("SELECT step, value FROM metrics WHERE name = 'eval/games' ORDER BY step").fetchall()
    assert evals == [(200, 8.0), (400, 8.0)]
    counts = con.execute("SELECT name, value FROM metrics WHERE step = 400 AND name IN "
                         "('eval/wins', 'eval/losses', 'eval/draws', 'eval/truncated')").fetchall()
    assert sum(v for _, v in counts) == 8
    # training episodes: one row each with outcome, return and length, begun with their training step
    train = con.execute("SELECT outcome, steps, reward, train_step FROM episodes WHERE kind = 'train' "
                        "AND outcome <> 'aborted'").fetchall()
    assert train and all(o in ("win", "loss", "terminated", "truncated") and 0 < n <= 30 and 0 <= s < 400
                         for o, n, _, s in train)
    assert con.execute("SELECT count(*) FROM episodes WHERE kind = 'train' AND NOT ended").fetchone()[0] == 0
    # the first 2 evaluation games of each evaluation are traced in full, and why explains them
    traced = con.execute("SELECT episode, train_step, begin_info FROM episodes WHERE kind = 'eval' "
                         "ORDER BY episode").fetchall()
    assert [s for _, s, _ in traced] == [200, 200, 400, 400]
    # begun as `tracelab eval --run` begins its games: with the world's params the evaluation plays (its spec's)
    assert json.loads(traced[2][2]) == {"kind": "eval", "train_step": 400, "eval_round": 1,
                                        "params": {"advanced": False, **WALK_ARGS, "p_toward": 0.5}}
    ep = traced[0][0]
    atom, t = con.execute("SELECT atom, t FROM changes WHERE episode = ? AND label = 'atLoc' AND new_lower = 1 "
                          "AND atom LIKE 'atLoc(red-agent-1,%' ORDER BY t DESC LIMIT 1", [ep]).fetchone()
    assert t >= 1
    text = render_why(explain(con, episode=ep, atom=atom, at=t, depth=2))
    assert atom in text and "action" in text
    assert con.execute("SELECT count(*) FROM steps WHERE episode = ?", [ep]).fetchone()[0] > 0
    con.close()
    state = load_checkpoint(run)
    assert state["step"] == 400 and checkpoint_path(run).exists()
    spec = load_env_policy(run / "policy", walk_source())[1]
    assert spec["network"] == {**spec["network"], "inputs": 4, "hidden": 64, "outputs": 5}
    assert spec["actions"]["names"] == ["up", "down", "left", "right", "nothing"]
    assert spec["env"] == walk_source().to_json() and spec["trained"]["step"] == 400
    # the policy of the best evaluation (the earliest of equals) is kept beside the final one
    con = open_run(run)
    rates = con.execute("SELECT step, value FROM metrics WHERE name = 'eval/method_win_rate' ORDER BY step").fetchall()
    con.close()
    best_step, best = max(rates, key=lambda sv: (sv[1], -sv[0]))
    kept = load_env_policy(run / "policy-best", walk_source())[1]["trained"]
    assert kept["step"] == best_step and kept["selected_by"]["value"] == pytest.approx(best)
    assert state["best_eval"] == (pytest.approx(best), best_step)


def test_resume_gives_the_same_networks_metrics_and_episodes_as_no_interruption(tmp_path):
    cfg = walk_config(steps=480, seed=11)
    straight, first, resumed = tmp_path / "straight", tmp_path / "first", tmp_path / "resumed"
    assert train_walk(cfg, straight) == 0
    assert train_walk(cfg, first, stop_at=246) == 130  # stops after the pass that crosses 246
    assert run_info(first).status == "interrupted"
    assert load_checkpoint(first)["step"] == 248
    # the checkpoint holds the config; the env is named again (a run never names the spec tracelab reads)
    assert main(["train", "--resume", str(first), *walk_argv(), "--run", str(resumed)]) == 0
    a, b = load_checkpoint(straight), load_checkpoint(resumed)
    assert a["step"] == b["step"] == 480
    assert torch.equal(a["learners"]["shared"]["params"], b["learners"]["shared"]["params"])
    assert torch.equal(a["learners"]["shared"]["adam_v"], b["learners"]["shared"]["adam_v"])
    np.testing.assert_array_equal(a["learners"]["shared"]["buffer"]["obs"], b["learners"]["shared"]["buffer"]["obs"])
    assert _metrics(straight) == {**_metrics(first), **_metrics(resumed)}
    assert _ended_training_episodes(straight) == sorted(_ended_training_episodes(first) +
                                                        _ended_training_episodes(resumed))
    assert run_info(resumed).meta["config"]["resumed_from"] == {"run": str(first), "step": 248}
    # the kept best policy carries over into the resumed run
    assert a["best_eval"] == b["best_eval"]
    assert load_env_policy(resumed / "policy-best", walk_source())[1]["trained"]["step"] == a["best_eval"][1]
    for name, weights in a["best_weights"].items():
        assert all(torch.equal(w, b["best_weights"][name][k]) for k, w in weights.items())


def test_the_learner_learns_to_walk_to_the_enemy_base():
    """A real assertion that learning happens: >= 95% wins after 4,000 steps (a random policy wins ~10%)."""
    cfg = TrainConfig(steps=4000, seed=0, warmup=200, envs=8, lr=3e-3, gamma=0.9, target_every=250, buffer=5000,
                      batch=64, eval_every=0, eval_games=200, eval_envs=50, log_every=1000, checkpoint_every=0,
                      reward_scale=1.0)
    trainer = walk_trainer(cfg, walk_source(p_toward=0.0))  # blue walks at random
    before = trainer.run_eval().win_rate
    assert trainer.train() == "finished"
    result = trainer.last_eval
    trainer.close()
    assert before < 0.5
    assert result.games == 200 and result.win_rate >= 0.95, result.to_dict()
    assert np.mean(result.win_steps) <= 8  # the shortest walk is 6 moves


def test_reward_scale_scales_what_the_learner_sees_and_nothing_that_is_logged():
    """--reward-scale multiplies the replay rewards only: the same seed plays the same games (warm-up, so
    no update changes the actions) and logs the same returns."""
    def buffered(scale):
        cfg = walk_config(steps=400, seed=5, warmup=1000, eval_every=0, reward_scale=scale)
        trainer = walk_trainer(cfg)
        trainer.train()
        st = trainer.learner.buffer.state()
        returns = trainer.episodes.returns.copy()
        trainer.close()
        return st, returns
    (one, ret_one), (small, ret_small) = buffered(1.0), buffered(0.01)
    np.testing.assert_array_equal(one["action"], small["action"])
    np.testing.assert_allclose(small["reward"], one["reward"] * 0.01, rtol=1e-6)
    assert np.abs(one["reward"]).max() >= 1  # the walk's unsafe (-1) and win (10) rewards happened
    np.testing.assert_array_equal(ret_one, ret_small)


def test_train_says_when_the_learner_sees_rewards_beyond_smooth_l1s_quadratic_zone(tmp_path, capsys):
    """GridWar's scenarios (train --scenario): the note reads the scenario's rewards."""
    quiet = tmp_path / "quiet.toml"  # the built-in map with the walk's rewards (up to 10)
    quiet.write_text('name = "quiet"\nwidth = 8\nheight = 8\nred_base = [7, 0]\nblue_base = [0, 7]\n'
                     'mountains = [[2, 3], [3, 3], [2, 4], [3, 4], [4, 4], [4, 5]]\nmax_steps = 30\n[rewards]\n' +
                     "".join(f"{k} = {v}\n" for k, v in asdict(WALK.rewards).items()))
    small = ["--total-timesteps", "40", "--num-envs", "4", "--learning-starts", "20", "--eval-every", "0",
             "--eval-games", "2", "--eval-envs", "2", "--trace-eval-games", "0", "--checkpoint-every", "0"]
    method = ["--reward-scale", "1"]  # the method's: base's hits are worth 400
    assert main(["train", "--scenario", "base", *small, *method, "--run", str(tmp_path / "a")]) == 0
    assert "note: the learner sees rewards up to 400, where Smooth L1 caps the gradient; --reward-scale 0.01" \
        in capsys.readouterr().err
    assert main(["train", "--scenario", "base", *small, "--reward-scale", "0.01", "--run", str(tmp_path / "b")]) == 0
    assert "note:" not in capsys.readouterr().err
    # the default scale (for GridWar's hundreds) on the walk's own rewards (up to 10): too small
    assert main(["train", "--scenario", str(quiet), *small, "--run", str(tmp_path / "c")]) == 0
    assert "note: the learner sees rewards up to 0.1 only (--reward-scale 0.01 suits rewards in the hundreds); " \
        "--reward-scale 0.1 puts them near 1" in capsys.readouterr().err


def test_masked_training_records_the_moves_the_shield_allows_in_the_next_state():
    """--mask: each stored transition carries the actions allowed where it lands (up, down, left, right,
    nothing on the 4x4 walk: a move off the map is forbidden), which bound the target's max."""
    cfg = walk_config(steps=400, seed=4, mask=True, eval_every=0)
    trainer = walk_trainer(cfg)
    trainer.train()
    st = trainer.learner.buffer.state()
    trainer.close()
    boot = st["discount"] > 0  # bootstrapped transitions: their next state is the one the mask describes
    x, y = st["next_obs"][boot, 0], st["next_obs"][boot, 1]
    expect = np.stack([y < 3, y > 0, x > 0, x < 3, np.ones_like(x, bool)], axis=1)
    assert boot.sum() > 100 and not expect.all()
    np.testing.assert_array_equal(st["next_allowed"][boot], expect)


def test_a_team_s_closing_transitions_carry_the_win_or_loss_term():
    """With several agents each learns from its own reward; the step that ends a game resets the world
    within the step (SAME_STEP), so the terminal rewards must come from final_info. Nearly every transition
    cut by the game's end or a death (discount 0) carries +-10 plus its small step term; the rest carry
    step terms only."""
    cfg = walk_config(steps=1200, seed=3, warmup=5000, eval_every=0)
    trainer = walk_trainer(cfg, walk_source(agents_per_team=2))
    trainer.train()
    st = trainer.learner.buffer.state()
    trainer.close()
    assert trainer.agents == 2
    closing = st["discount"] == 0
    assert closing.sum() >= 20
    won_or_lost = np.abs(st["reward"][closing]) > 8.5
    assert won_or_lost.mean() > 0.9, st["reward"][closing]
    assert (st["reward"][closing] > 8.5).any() and (st["reward"][closing] < -8.5).any()
    assert (np.abs(st["reward"][~closing]) <= 1.0).all()  # step terms only: -0.1, or -1 when unsafe


@pytest.mark.parametrize("share", [1.0, 0.0])
def test_explore_scripted_takes_exploring_actions_from_the_scripted_policy(share):
    """--explore-scripted 1: every exploring move is the spec's scripted choice (`[agents] script`), a
    step towards blue's base at (0, 3) (one always exists on the open walk); 0: uniform, so other actions
    appear too."""
    cfg = walk_config(steps=400, seed=6, explore_scripted=share, warmup=5000, eval_every=0)
    trainer = walk_trainer(cfg)
    trainer.train()
    st = trainer.learner.buffer.state()
    trainer.close()
    steps = st["discount"] > 0  # the closing transitions' next obs is the terminal one: keep the rest
    dist = lambda o: o[:, 0] + (3 - o[:, 1])  # noqa: E731  Manhattan distance of red to (0, 3)
    closer = dist(st["next_obs"][steps]) == dist(st["obs"][steps]) - 1
    assert steps.sum() > 100
    assert closer.all() if share == 1.0 else closer.mean() < 0.7


def test_saved_policy_round_trips_and_plain_torch_loads_it(tmp_path):
    cfg = walk_config(steps=200, seed=2, eval_every=0)
    trainer = walk_trainer(cfg)
    trainer.train()
    path = trainer.save_policy(tmp_path / "policy")
    loaded, spec = load_env_policy(path, walk_source())
    obs = np.random.default_rng(0).integers(0, 4, (50, 4)).astype(np.float32)
    np.testing.assert_array_equal(loaded.act(obs), trainer.policy.act(obs))
    assert len(set(loaded.act(obs).tolist())) > 1  # a trained network: not one action everywhere
    net = torch.nn.Sequential(torch.nn.Linear(4, 64), torch.nn.Tanh(), torch.nn.Linear(64, 5))
    net.load_state_dict(torch.load(path / "policy.pt", weights_only=True)["shared"])
    with torch.no_grad():
        assert (net(torch.from_numpy(obs)).argmax(1).numpy() == loaded.act(obs)).all()
    assert spec["observation"] == {"size": 4, "encoding": "Box, 4 numbers"}
    assert spec["networks"] == {"shared": [0]} and spec["env"] == walk_source().to_json()
    trainer.close()


def test_a_config_with_retired_fields_still_loads():
    """split_networks and backend went with RuleSim's trainer, the scenario's fields into the world's params: a
    run's config (a checkpoint's, checked against its schema) that holds them loads without them."""
    from tracelab.train.config import RETIRED_FIELDS, config_schema
    from tracelab.validation import check
    old = {"scenario": "nonmarkov", "non_markov": True, "agents": None, "opponent_p": 0.7, "eval_p": 0.3,
           "kernel": "lanes"}
    check(old, config_schema(), "config")
    cfg = TrainConfig.from_dict({**old, "split_networks": True, "backend": "reference"})
    assert cfg.kernel == "lanes"
    assert not {"split_networks", "backend", *RETIRED_FIELDS} & set(cfg.to_dict())


def test_ctrl_c_leaves_an_interrupted_run_with_a_checkpoint(tmp_path):
    run = tmp_path / "run"
    status, out, err = ctrl_c_once_training(["train", "--scenario", "base", "--steps", "10000000", "--log-every",
                                             "64", "--eval-every", "0", "--warmup", "64", "--run", str(run)], run)
    assert status == 130, err
    assert "interrupted at step" in out and "--resume" in out
    assert run_info(run).status == "interrupted"
    state = load_tensors(checkpoint_path(run), 10**9)  # --scenario base trains through its spec: its format
    assert state["step"] > 0
    con = open_run(run)
    logged = con.execute("SELECT max(step) FROM metrics").fetchone()[0]
    open_eps = con.execute("SELECT count(*) FROM episodes WHERE NOT ended").fetchone()[0]
    con.close()
    assert logged <= state["step"] and open_eps == 0
