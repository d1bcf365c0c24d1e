"""The trainer's parts (tracelab/train: rngs, exploration, update_schedule, episode_log, best_policy,
metric_log) each save and load themselves; a trainer's state is theirs side by side, so a
trainer loaded from another's state continues exactly as the other does."""
from __future__ import annotations

import numpy as np
import torch

from tracelab.train.best_policy import BestPolicy
from tracelab.train.config import TrainConfig
from tracelab.train.episode_log import EpisodeLog
from tracelab.train.exploration import Exploration
from tracelab.train.rngs import Generators
from tracelab.train.update_schedule import UpdateSchedule
from train_helpers import walk_config, walk_trainer


def test_a_trainer_loaded_from_anothers_state_continues_as_it_does() -> None:
    """No files: EnvTrainer.state() into a fresh EnvTrainer's load_state(); both train on to the same weights,
    replay buffers and episode counts (the worlds rebuilt by replaying their actions)."""
    cfg = walk_config(steps=500, seed=4, eval_every=0)
    first, second = walk_trainer(cfg), walk_trainer(cfg)
    try:
        first.train(stop_at=248)
        assert first.episodes.lengths.any()  # games in progress: the load must replay them
        second.load_state(first.state())
        for tr in (first, second):
            tr.train()
        one, two = first.learner, second.learner
        for k, v in one.online_weights().items():
            torch.testing.assert_close(two.online_weights()[k], v, rtol=0, atol=0)
        np.testing.assert_array_equal(one.buffer.state()["obs"], two.buffer.state()["obs"])
        assert first.episodes.next_episode == second.episodes.next_episode > 0
        assert first.schedule.state() == second.schedule.state()
    finally:
        first.close()
        second.close()


def test_the_checkpoint_keys_are_the_parts_states_side_by_side() -> None:
    tr = walk_trainer(walk_config(steps=100, seed=1))
    try:
        st = tr.state()
        parts = (tr.rngs, tr.schedule, tr.metrics, tr.best, tr.episodes)
        assert {k for p in parts for k in p.state()} <= set(st)
        assert set(st["games"]) == {"ep_len", "ep_return", "ep_id", "ep_start", "obs"}
        assert st["env_actions"].shape == (0, 4)  # the worlds' actions since their reset: none yet
    finally:
        tr.close()


def test_the_generators_come_from_the_seed_and_load_back() -> None:
    a, b = Generators(7), Generators(7)
    assert a.env_seed() == b.env_seed() and a.eval_seed(3) == b.eval_seed(3) != a.eval_seed(4)
    a.numpy.random(5)
    torch.rand(3, generator=a.torch)
    b.load_state(a.state())
    assert a.numpy.random() == b.numpy.random()
    assert torch.equal(torch.rand(2, generator=a.torch), torch.rand(2, generator=b.torch))


def test_exploration_is_random_in_warm_up_and_keeps_to_the_allowed_actions() -> None:
    cfg = TrainConfig(warmup=100, steps=1000, eps_end=0.0)
    ex = Exploration(cfg, np.random.default_rng(0))
    assert ex.epsilon(0) == 1.0 and ex.epsilon(1000) == 0.0
    masks = np.zeros((50, 2, 5), np.float32)
    masks[..., 3] = 1.0
    explore, random = ex.draw(0, (50, 2), 5, masks)
    assert explore.all() and (random == 3).all()


def test_the_update_schedule_carries_the_fraction_and_copies_the_target_once_a_block() -> None:
    class Counting:
        def __init__(self) -> None:
            self.updates, self.syncs = 0, 0
            self.buffer = type("B", (), {"size": 64})()

        def update(self, rng: np.random.Generator) -> None:
            self.updates += 1

        def sync_target(self) -> None:
            self.syncs += 1

    cfg = TrainConfig(warmup=10, batch=32, updates_per_step=0.25, target_every=100)
    sched, learner, rng = UpdateSchedule(cfg, worlds=2), Counting(), np.random.default_rng(0)
    for step in range(2, 402, 2):
        sched.run(step, [learner], rng)
    assert learner.updates == int((400 - 10 + 2) / 2 * 0.5) and learner.syncs == 4
    again = UpdateSchedule(cfg, worlds=2)
    again.load_state(sched.state())
    assert again.state() == sched.state() == {"update_credit": sched.credit, "synced_block": 4}


def test_the_episode_log_numbers_ends_and_loads_its_games() -> None:
    log = EpisodeLog(3, writer=None)
    log.begin(np.arange(3), 0)
    log.add_step(np.array([1.0, 2.0, 3.0]))
    log.end(np.array([1]), ["win"])
    log.begin(np.array([1]), 3)
    assert log.ids.tolist() == [0, 3, 2] and log.take_returns() == [2.0] and log.take_returns() == []
    other = EpisodeLog(3, writer=None)
    other.load_state(log.state())
    assert other.ids.tolist() == [0, 3, 2] and other.starts.tolist() == [0, 3, 0] and other.new_id() == 4
    other.renumber(10)
    assert other.ids.tolist() == [10, 11, 12]


def test_the_best_policy_keeps_a_copy_of_the_earliest_best() -> None:
    best, w = BestPolicy(), {"shared": {"w": torch.zeros(2)}}
    assert best.consider(0.5, 100, w)
    w["shared"]["w"] += 1  # the live weights move on; the kept ones do not
    assert not best.consider(0.5, 200, w) and best.eval == (0.5, 100)
    assert torch.equal(best.weights["shared"]["w"], torch.zeros(2))
    assert best.consider(0.75, 300, w) and torch.equal(best.weights["shared"]["w"], torch.ones(2))
