"""Reward decomposition (`train --decompose`, Juozapaitis et al. 2019): one Q head per reward term of a spec
world, each learning its term's return with the shared greedy action of the summed Q; the heads sum to the
ordinary Q; the policy file names the terms; traced evaluations store each action's value by term, and
`why --action` prints them."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from tracelab.cli import main
from tracelab.store.reader import open_run
from tracelab.train.dqn import DecomposedDQN, make_q_network
from tracelab.train.qnet import NetSpec, NumpyQ
from tracelab.train.replay import ReplayBuffer

TAXI = Path(__file__).resolve().parents[1] / "rules" / "toytext" / "taxi.toml"
TERMS = ("a", "b", "c")


def _decomposed(seed: int) -> tuple[NetSpec, DecomposedDQN]:
    spec = NetSpec(4, (16,), 5, terms=TERMS)
    learner = DecomposedDQN(make_q_network(spec, torch.Generator().manual_seed(seed)),
                            ReplayBuffer(64, 4, 5, 32, reward_terms=len(TERMS)), lr=1e-2)
    rng = np.random.default_rng(0)
    k = 64
    learner.buffer.add(rng.normal(size=(k, 4)).astype(np.float32), rng.integers(0, 5, k),
                       rng.normal(size=(k, len(TERMS))).astype(np.float32), rng.normal(size=(k, 4)).astype(np.float32),
                       rng.choice([0.0, 0.9], k).astype(np.float32))
    return spec, learner


def test_the_heads_sum_to_the_ordinary_q_and_each_learns_its_terms_target():
    """Acting's Q (numpy) is the sum of the module's heads; one update's loss is, per term, the Smooth L1
    against r_k + discount * Q_target,k(s', a*) with a* the greedy action of the summed target Q, and those
    targets sum to the ordinary DQN target on the summed reward."""
    spec, learner = _decomposed(0)
    learner.target_network.load_state_dict(make_q_network(spec, torch.Generator().manual_seed(1)).state_dict())
    obs = np.random.default_rng(1).normal(size=(20, 4)).astype(np.float32)
    q = NumpyQ(spec, {k: v.numpy() for k, v in learner.q_network.state_dict().items()})
    with torch.no_grad():
        heads = learner.q_terms(learner.q_network, torch.from_numpy(obs)).numpy()
    assert heads.shape == (20, 3, 5)
    np.testing.assert_allclose(q.per_term(obs), heads, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(q(obs), heads.sum(axis=1), rtol=1e-5, atol=1e-6)

    data = learner.buffer.sample_batch(np.random.default_rng(3))
    s, a, r, s2, d = (torch.from_numpy(x.copy()) for x in data[:5])
    assert r.shape == (32, 3)
    with torch.no_grad():
        nxt = learner.q_terms(learner.target_network, s2)                        # [B, K, A]
        best = nxt.sum(1).argmax(1)
        y = r + d * nxt[torch.arange(32), :, best]
        ordinary = r.sum(1, keepdim=True) + d * nxt.sum(1).max(1, keepdim=True).values
        torch.testing.assert_close(y.sum(1, keepdim=True), ordinary)             # targets sum to DQN's
        taken = learner.q_terms(learner.q_network, s).gather(2, a.unsqueeze(1).expand(-1, 3, 1)).squeeze(2)
        want = sum(torch.nn.functional.smooth_l1_loss(taken[:, k], y[:, k]) for k in range(3))
    learner.update(np.random.default_rng(3))
    assert learner.take_loss() == pytest.approx(float(want), rel=1e-5)


def test_train_decompose_on_taxi_stores_q_by_term_and_why_prints_it(tmp_path, capsys):
    run = tmp_path / "taxi"
    assert main(["train", "--env", str(TAXI), "--decompose", "--total-timesteps", "600", "--num-envs", "4",
                 "--learning-starts", "200", "--eval-every", "0", "--eval-games", "1", "--trace-eval-games", "1",
                 "--seed", "3", "--run", str(run)]) == 0
    first = capsys.readouterr().err.splitlines()[0]
    assert "the readable learner" in first and "(given: --decompose)" in first
    network = json.loads((run / "policy" / "policy.json").read_text())["network"]
    assert network["terms"] == ["plain(taxi)", "illegal(taxi)", "delivered(taxi)"]
    con = open_run(run)
    try:
        rows = con.execute('SELECT episode, step, terms, term_values, "values" FROM decisions').fetchall()
    finally:
        con.close()
    assert rows
    for _, _, terms, by_term, values in rows:  # every stored decision: its heads sum to its Q-values
        assert terms == network["terms"]
        np.testing.assert_allclose(np.reshape(by_term, (3, -1)).sum(axis=0), values, rtol=1e-4, atol=1e-4)
    episode, step = rows[0][:2]
    assert main(["why", str(run), "--action", "taxi", "--episode", str(episode), "--at", str(step)]) == 0
    out = capsys.readouterr().out
    assert "expected return by reward term" in out and "delivered(taxi)" in out
    # the checkpoint keeps each transition's reward by term and resumes
    assert main(["train", "--resume", str(run), "--env", str(TAXI), "--total-timesteps", "700"]) == 0


def test_a_plain_policy_stores_no_terms_and_a_gridwar_scenario_trains_decomposed(tmp_path, capsys):
    """Since `train --scenario` trains GridWar's spec, its reward terms are the spec's: --decompose takes it
    (before: refused, RuleSim's trainer had no terms)."""
    run = tmp_path / "plain"
    assert main(["train", "--env", str(TAXI), "--total-timesteps", "300", "--num-envs", "4",
                 "--learning-starts", "200", "--eval-every", "0", "--eval-games", "1", "--trace-eval-games", "1",
                 "--run", str(run)]) == 0
    assert "terms" not in json.loads((run / "policy" / "policy.json").read_text())["network"]
    con = open_run(run)
    try:
        counts = con.execute("SELECT count(*), count(terms), count(term_values) FROM decisions").fetchall()[0]
    finally:
        con.close()
    assert counts[0] > 0 and counts[1:] == (0, 0)
    capsys.readouterr()
    assert main(["train", "--scenario", "base", "--decompose", "--total-timesteps", "8", "--num-envs", "4",
                 "--learning-starts", "4", "--eval-every", "0", "--eval-games", "1", "--trace-eval-games", "1",
                 "--run", str(tmp_path / "g")]) == 0
    terms = json.loads((tmp_path / "g" / "policy" / "policy.json").read_text())["network"]["terms"]
    assert len(terms) > 1, terms
