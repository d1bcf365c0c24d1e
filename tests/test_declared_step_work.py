"""The Python work around a small batch's compiled step (tracelab/envs/declared/vector_world.py): a one-world
GridWar batch takes its np_random numbers in blocks of many steps, and every agent's observation and reward
is its own copy of the step's reads, and each world's steps into its episode are counted inside the
compiled step (the ends it writes with them). (Speed itself is bench env's; this holds the work that it
counts.)"""
from __future__ import annotations

import numpy as np
import pytest

from tracelab.bench.sims import team_spec
from tracelab.envs.declared.gridwar import scenario_spec
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.vector_world import DeclaredWorlds
from tracelab.game.scenario import builtin_scenario


class CountingGenerator:
    """A np.random.Generator that counts its random(n) calls (a block of numbers each)."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.blocks = 0

    def random(self, *args: object) -> object:
        self.blocks += 1
        return self.rng.random(*args)

    def __getattr__(self, name: str) -> object:
        return getattr(self.rng, name)


def test_a_one_world_batch_refills_its_numbers_once_in_64_steps() -> None:
    worlds = DeclaredWorlds(team_spec(1), 1, "counting")
    draws = len(worlds.one._before)
    assert draws > 0  # the scripted opponent's choices are drawn every step
    rng = CountingGenerator(3)
    worlds.use_generators([rng])
    worlds.reset(np.arange(1))
    actions = np.random.default_rng(0).integers(0, worlds.n_actions, (256, 1, worlds.n_agents))
    episodes = 1
    for a in actions:
        worlds.step(a)
        if worlds.terminated()[0] or worlds.truncated(None)[0]:
            worlds.reset(np.arange(1))  # a restart takes a number of the same block
            episodes += 1
    numbers = 256 * draws + episodes * len(worlds.one._choices)
    # main's block was 8 steps' numbers (at least 64): 256 steps of 1v1 refilled ~13 times
    assert rng.blocks <= numbers // (64 * draws) + 2, (rng.blocks, numbers)


def test_each_agents_observation_and_reward_is_its_own_copy() -> None:
    worlds = DeclaredWorlds(team_spec(2), 1, "counting")
    worlds.use_generators([np.random.default_rng(5)])
    worlds.reset(np.arange(1))
    worlds.step(np.zeros((1, worlds.n_agents), np.int64))
    width = worlds.one.observation_program.width
    numbers = worlds._observer.read(worlds.engine)
    for agent in range(worlds.n_agents):
        obs = worlds.observations(agent)
        np.testing.assert_array_equal(obs, numbers[:, agent * width:(agent + 1) * width])
        obs[:] = -7  # the caller's to keep or change: the next read is the step's again
        np.testing.assert_array_equal(worlds.observations(agent), numbers[:, agent * width:(agent + 1) * width])
        reward = worlds.rewards(agent)
        reward[:] = 99.0
        assert worlds.rewards(agent)[0] != 99.0


@pytest.mark.parametrize("worlds, kernel", [(1, "counting"), (64, "lanes")])
def test_a_step_counts_in_its_episode_and_truncates_at_the_specs_limit(worlds: int, kernel: str) -> None:
    """steps counts each world's steps since its reset (an engine_step outside the episodes does not
    count); at the spec's max_steps a world that did not terminate is truncated, on that step, not one
    later; the ends read are the caller's copies."""
    path, params = scenario_spec(builtin_scenario("base"))
    batch = DeclaredWorlds(load_spec(path, **{**params, "max_steps": 3}), worlds, kernel)
    assert batch.kernel == kernel
    batch.use_generators([np.random.default_rng(seed) for seed in range(worlds)])
    batch.reset(np.arange(worlds))
    stay = np.full((worlds, batch.n_agents), -1, np.int64)  # no red action: no game ends in 3 steps
    for step in (1, 2):
        batch.step(stay)
        assert batch.steps.tolist() == [step] * worlds
        assert not batch.truncated(None).any() and not batch.terminated().any()
    batch.engine_step(stay, np.full_like(batch._picks, -1))
    assert batch.steps.tolist() == [2] * worlds
    batch.step(stay)
    assert batch.steps.tolist() == [3] * worlds
    truncated = batch.truncated(None)
    assert truncated.all()
    truncated[:] = False
    batch.terminated()[:] = True
    assert batch.truncated(None).all() and not batch.terminated().any()
    batch.reset(np.arange(1))
    assert batch.steps.tolist() == [0] + [3] * (worlds - 1)
