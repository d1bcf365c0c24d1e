"""The two learners: the fused update equals the readable one (autograd + torch.optim.Adam,
tracelab/train/dqn.py) for every option the fused one supports; the readable one's options (Double DQN,
a dueling head, more layers, any torch module, a new loss) train through EnvTrainer and the CLI, are recorded in
checkpoints and policies, and resume; `--learner auto` says when it takes the readable one."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from tracelab.cli import main
from tracelab.engine.safe_files import FileRefused
from tracelab.errors import UserError
from tracelab.train.dqn import DQN, make_q_network
from tracelab.train.env_checkpoint import checkpoint_path, load_env_checkpoint
from tracelab.train.env_policy import load_env_policy
from tracelab.train.learner import DQNLearner
from tracelab.train.memory import memory_limit
from tracelab.train.network import state_dict_views
from tracelab.train.qnet import NetSpec, NumpyQ
from tracelab.train.replay import ReplayBuffer
from tracelab.train.torch_files import load_tensors
from train_helpers import train_walk, walk_argv, walk_config, walk_source, walk_trainer


def _filled(buffer: ReplayBuffer, masked: bool) -> None:
    rng = np.random.default_rng(0)
    k = 100
    allowed = rng.random((k, 5)) < 0.5
    allowed[:, 4] = True  # do nothing is always allowed
    buffer.add((rng.normal(size=(k, 4)) * 3).astype(np.float32), rng.integers(0, 5, k),
               (rng.normal(size=k) * 5).astype(np.float32), (rng.normal(size=(k, 4)) * 3).astype(np.float32),
               rng.choice([0.0, 0.99], k).astype(np.float32), allowed if masked else None)


@pytest.mark.parametrize("masked", [False, True])
def test_fused_update_equals_the_readable_one_loss_and_weights(masked):
    """Same init, same minibatches: after 40 updates (two target copies) the fused learner's weights and
    sampled losses are the readable learner's; masked (--mask): the max runs over the actions allowed in s'."""
    torch.set_num_threads(1)
    spec = NetSpec(4, (16,), 5)
    fused = DQNLearner(spec, lr=1e-2, batch=32, buffer=100, generator=torch.Generator().manual_seed(0),
                       masked=masked)
    readable = DQN(make_q_network(spec, torch.Generator().manual_seed(0)), ReplayBuffer(100, 4, 5, 32, masked),
                   lr=1e-2)
    # the same seed draws the same network in both: the fused row reads back as the module's weights
    for k, v in readable.online_weights().items():
        assert torch.equal(v, fused.online_weights()[k])
    _filled(fused.buffer, masked)
    _filled(readable.buffer, masked)
    fused.params[1] += 0.1  # a target network that differs from the online one
    readable.target_network.load_state_dict(state_dict_views(fused.params[1], spec))
    rng_f, rng_r = np.random.default_rng(5), np.random.default_rng(5)
    compared = 0
    for i in range(40):
        fused.update(rng_f)
        readable.update(rng_r)
        if masked and i == 0:
            ok = readable.buffer.b_next_penalty == 0.0
            assert not ok.all() and ok[:, 4].all()  # the mask bites in these minibatches
        f_loss, r_loss = fused.take_loss(), readable.take_loss()
        if f_loss is not None:  # the fused learner samples every 16th update's loss
            assert f_loss == pytest.approx(r_loss, rel=1e-5)
            compared += 1
        if i in (12, 30):
            fused.sync_target()
            readable.sync_target()
    assert compared == 3
    for key, value in readable.online_weights().items():
        torch.testing.assert_close(fused.online_weights()[key], value, rtol=1e-5, atol=1e-6)
    assert fused.q_max_mean() == pytest.approx(readable.q_max_mean(), rel=1e-5)


def test_double_dqn_takes_the_target_networks_value_of_the_online_networks_choice():
    """One update by hand: the target is r + discount * Q_target(s', argmax_a Q_online(s', a)), which differs
    from the max target here (the two networks disagree on a')."""
    torch.manual_seed(0)
    buffer = ReplayBuffer(50, 4, 5, 50)
    _filled(buffer, False)
    learners = {double: DQN(make_q_network(NetSpec(4, (8,), 5), torch.Generator().manual_seed(1)),
                            ReplayBuffer(50, 4, 5, 50), lr=1e-3, double_dqn=double) for double in (False, True)}
    for lr in learners.values():
        _filled(lr.buffer, False)
        lr.target_network.load_state_dict(make_q_network(NetSpec(4, (8,), 5), torch.Generator().manual_seed(2))
                                          .state_dict())
    data = learners[True].buffer.sample_batch(np.random.default_rng(3))
    obs, actions, rewards, next_obs, discounts = (torch.from_numpy(x.copy()) for x in data[:5])
    online, target = learners[True].q_network, learners[True].target_network
    with torch.no_grad():
        pick = online(next_obs).argmax(1, keepdim=True)
        double_y = rewards + discounts * target(next_obs).gather(1, pick)
        max_y = rewards + discounts * target(next_obs).max(1, keepdim=True).values
        want = {True: torch.nn.functional.smooth_l1_loss(online(obs).gather(1, actions), double_y).item(),
                False: torch.nn.functional.smooth_l1_loss(online(obs).gather(1, actions), max_y).item()}
    assert abs(want[True] - want[False]) > 1e-3
    for double, lr in learners.items():
        lr.update(np.random.default_rng(3))
        assert lr.take_loss() == pytest.approx(want[double], rel=1e-6)


@pytest.mark.parametrize("dueling", [False, True])
def test_numpy_acting_computes_the_modules_q_values(dueling):
    """The module is built from the description (its names are checked as it loads its weights); acting
    computes its forward pass a second time, in numpy: the two agree."""
    spec = NetSpec(6, (16, 8), 5, dueling)
    module = make_q_network(spec, torch.Generator().manual_seed(0))
    obs = np.random.default_rng(0).normal(size=(20, 6)).astype(np.float32)
    q = NumpyQ(spec, {k: v.numpy() for k, v in module.state_dict().items()})(obs)
    with torch.no_grad():
        np.testing.assert_allclose(q, module(torch.from_numpy(obs)).numpy(), rtol=1e-5, atol=1e-6)


def test_a_dueling_double_dqn_two_layer_run_learns_resumes_and_its_policy_loads(tmp_path):
    """Through `tracelab train`: auto falls back to the readable learner and says so in one line; the
    checkpoint names the learner and resumes as an uninterrupted run; the policy records the architecture
    and tracelab eval plays it."""
    cfg = walk_config(steps=480, seed=11, hidden="32,32", double_dqn=True, dueling=True)
    straight, first = tmp_path / "straight", tmp_path / "first"
    assert train_walk(cfg, straight) == 0
    assert train_walk(cfg, first, stop_at=246) == 130
    checkpoint = lambda run: load_tensors(checkpoint_path(run), 10**9)  # noqa: E731
    state = checkpoint(first)
    assert state["learner"] == "readable" and set(state["learners"]["shared"]["online"]) == \
        set(NetSpec(4, (32, 32), 5, True).state_dict_shapes())
    assert main(["train", "--resume", str(first), *walk_argv()]) == 0
    a, b = checkpoint(straight), checkpoint(first)
    for key in ("online", "target"):
        for name, value in a["learners"]["shared"][key].items():
            assert torch.equal(value, b["learners"]["shared"][key][name]), (key, name)
    assert a["learners"]["shared"]["adam"]["advantage.weight"]["step"] == \
        b["learners"]["shared"]["adam"]["advantage.weight"]["step"] > 0
    policy, spec = load_env_policy(straight / "policy", walk_source())
    assert spec["network"]["hidden"] == [32, 32] and spec["network"]["dueling"] is True
    obs = np.random.default_rng(0).integers(0, 4, (50, 4)).astype(np.float32)
    trained = make_q_network(NetSpec(4, (32, 32), 5, dueling=True))
    trained.load_state_dict(torch.load(straight / "policy" / "policy.pt", weights_only=True)["shared"])
    with torch.no_grad():
        greedy = trained(torch.from_numpy(obs)).argmax(1).numpy()
    np.testing.assert_array_equal(policy.act(obs), greedy)
    assert main(["eval", str(straight / "policy"), *walk_argv(), "--games", "4", "--json"]) == 0


def test_train_says_in_its_first_line_which_learner_runs_and_why(tmp_path, capsys):
    common = ["train", "--scenario", "base", "--total-timesteps", "8", "--num-envs", "4", "--learning-starts", "4",
              "--eval-every", "0", "--eval-games", "2", "--trace-eval-games", "1", "--eval-envs", "2",
              "--reward-scale", "0.01"]
    first_line = lambda: capsys.readouterr().err.splitlines()[0]  # noqa: E731
    assert main([*common, "--run", str(tmp_path / "a"), "--hidden", "8,8", "--dueling"]) == 0
    assert first_line().split(" steps with ")[1].split("; torch on")[0] == (
        "the readable learner (tracelab/train/dqn.py; --learner auto: the fused one supports one hidden layer "
        "without --double-dqn, --dueling or --decompose (given: --dueling, --hidden 8,8))")
    assert load_tensors(checkpoint_path(tmp_path / "a"), 10**9)["learner"] == "readable"
    assert main([*common, "--run", str(tmp_path / "b")]) == 0
    assert "with the fused learner (tracelab/train/learner.py, dqn.py's update written by hand; --learner auto " \
           "takes it for the method's network; an edited dqn.py trains with --learner readable)" in first_line()
    assert load_tensors(checkpoint_path(tmp_path / "b"), 10**9)["learner"] == "fused"
    assert main([*common, "--run", str(tmp_path / "r"), "--learner", "readable"]) == 0
    assert "with the readable learner (tracelab/train/dqn.py, --learner readable); torch on" in first_line()
    assert main([*common, "--run", str(tmp_path / "c"), "--learner", "fused", "--double-dqn"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["tracelab: error: learner fused supports one hidden layer without --double-dqn, --dueling or "
                   "--decompose (given: --double-dqn); use --learner readable (or auto)"]
    assert not (tmp_path / "c").exists()


def test_any_torch_module_trains_through_the_python_api(tmp_path):
    """A custom module (here with a LayerNorm) trains with the readable learner; its policy says `custom`
    and tracelab refuses to rebuild it from the file; its checkpoint loads with the same module and a
    trainer built with it continues from there."""
    def network(inputs: int, actions: int) -> torch.nn.Module:
        return torch.nn.Sequential(torch.nn.Linear(inputs, 32), torch.nn.LayerNorm(32), torch.nn.ReLU(),
                                   torch.nn.Linear(32, actions))
    cfg = walk_config(steps=400, seed=1)
    trainer = walk_trainer(cfg, run_dir=tmp_path / "run", network=network)
    assert trainer.learner_kind == "readable" and trainer.train() == "finished"
    assert isinstance(trainer.learner.q_network[1], torch.nn.LayerNorm)
    trainer.close()
    spec = json.loads((tmp_path / "run" / "policy" / "policy.json").read_text())
    assert "LayerNorm" in spec["network"]["custom"]
    with pytest.raises(ValueError, match="a custom torch module"):
        load_env_policy(tmp_path / "run" / "policy", walk_source())
    with pytest.raises(FileRefused, match="custom torch module"):
        load_env_checkpoint(tmp_path / "run", walk_source(), memory_limit())
    state = load_env_checkpoint(tmp_path / "run", walk_source(), memory_limit(), network=network)
    again = walk_trainer(cfg, network=network)
    again.load_state(state)
    for k, v in again.learner.online_weights().items():
        assert torch.equal(v, state["learners"]["shared"]["online"][k])
    again.close()
    with pytest.raises(UserError, match="readable learner"):
        walk_trainer(walk_config(learner="fused"), network=network)


class ConservativeDQN(DQN):
    """docs/training.md's worked example of a new loss, as written there: a conservative (CQL) term."""
    alpha = 0.5

    def loss(self, q, actions, td_target):
        conservative = (torch.logsumexp(q, dim=1, keepdim=True) - q.gather(1, actions)).mean()
        return super().loss(q, actions, td_target) + self.alpha * conservative


def test_a_new_loss_is_a_subclass_and_trains_through_the_trainer(tmp_path):
    """The worked example: its loss is the method's plus the conservative term, it trains through
    EnvTrainer(learner_class=...) into a run whose checkpoint resumes with the same class."""
    learner = ConservativeDQN(make_q_network(NetSpec(4, (8,), 5), torch.Generator().manual_seed(1)),
                              ReplayBuffer(50, 4, 5, 50), lr=1e-3)
    _filled(learner.buffer, False)
    data = learner.buffer.sample_batch(np.random.default_rng(3))
    obs, actions, rewards, next_obs, discounts = (torch.from_numpy(x.copy()) for x in data[:5])
    with torch.no_grad():
        q = learner.q_network(obs)
        y = rewards + discounts * learner.target_network(next_obs).max(1, keepdim=True).values
        taken = q.gather(1, actions)
        want = torch.nn.functional.smooth_l1_loss(taken, y) + 0.5 * (torch.logsumexp(q, 1, keepdim=True) - taken).mean()
    learner.update(np.random.default_rng(3))
    assert learner.take_loss() == pytest.approx(want.item(), rel=1e-6)
    cfg = walk_config(steps=400, seed=1)
    trainer = walk_trainer(cfg, run_dir=tmp_path / "run", learner_class=ConservativeDQN)
    assert isinstance(trainer.learner, ConservativeDQN) and trainer.train() == "finished"
    trainer.close()
    state = load_env_checkpoint(tmp_path / "run", walk_source(), memory_limit())
    assert state["learner"] == "readable"
    again = walk_trainer(replace(cfg, steps=600), learner_class=ConservativeDQN)
    again.load_state(state)
    assert again.step == 400 and again.train() == "finished"
    assert again.learner.updates > state["learners"]["shared"]["updates"]
    again.close()
