"""GridWar's vector env through gym.make_vec (the declared DeclaredVectorEnv over rules/gridworld/war*.toml):
a team of several red agents a world (observations [W, agents, D], actions [W, agents]) steps each world
as the PettingZoo env seeded seed + i; same-step autoreset never mixes two episodes in a stacked
observation; every world truncates at the step limit. One agent's worlds against single envs, seeding and
gymnasium's wrappers are tests/test_declared_vector_env.py's and tests/test_gym_gridwar.py's."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

import tracelab.envs  # noqa: F401  (registers the ids)
from tracelab.envs.declared.gridwar import parallel_env
from tracelab.envs.declared.vector_env import DeclaredVectorEnv

BASE, ADVANCED, NONMARKOV = "tracelab/GridWar-base-v0", "tracelab/GridWar-advanced-v0", "tracelab/GridWar-nonmarkov-v0"


def test_make_vec_of_a_team_is_the_team_vector_env() -> None:
    env = gym.make_vec(BASE, num_envs=4, agents_per_team=3, opponent_p=0.2)
    assert isinstance(env, DeclaredVectorEnv) and env.n_agents == 3
    assert env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert env.world_spec.params["p_toward"] == 0.2
    assert env.single_observation_space.shape == (3, 12)  # each agent's: x, y of the six agents
    assert env.single_action_space == gym.spaces.MultiDiscrete([5] * 3)
    assert env.action_space == batch_space(env.single_action_space, 4)
    obs, info = env.reset(seed=0)
    assert obs.shape == (4, 3, 12) and env.observation_space.contains(obs)
    assert info["action_mask"].shape == (4, 3, 5) and info["_action_mask"].all()
    obs, reward, terminated, truncated, info = env.step(np.full((4, 3), 4))  # every agent: nothing
    assert reward.shape == terminated.shape == truncated.shape == (4,)
    assert info["agent_reward"].shape == (4, 3) and np.allclose(info["agent_reward"].sum(axis=1), reward)
    with pytest.raises(ValueError, match="actions must be 4 x 3 integers in -1..4"):
        env.step(np.full(4, 0))


def test_each_team_world_steps_as_the_pettingzoo_env_seeded_seed_plus_i() -> None:
    """gym.make_vec of a 2v2 game: world i gives the PettingZoo env's observations, rewards (each agent's)
    and ends for the same actions, reset with seed s + i (-1 in the vector env: the agent left out)."""
    worlds, seed = 3, 7
    vec = gym.make_vec(BASE, num_envs=worlds, agents_per_team=2, max_steps=15)
    singles = [parallel_env(BASE, agents_per_team=2, max_steps=15) for _ in range(worlds)]
    names = singles[0].possible_agents
    obs, info = vec.reset(seed=seed)
    for i, env in enumerate(singles):
        one, infos = env.reset(seed=seed + i)
        assert [obs[i, j].tolist() for j in range(2)] == [one[a].tolist() for a in names]
        masks = [infos[a]["action_mask"].tolist() for a in names]
        assert [info["action_mask"][i, j].tolist() for j in range(2)] == masks
    rng, ends = np.random.default_rng(0), 0
    for k in range(60):
        actions = rng.integers(-1, 5, (worlds, 2))
        obs, reward, term, trunc, info = vec.step(actions)
        for i, env in enumerate(singles):
            one, rewards, te, tr, infos = env.step({a: int(x) for a, x in zip(names, actions[i]) if x >= 0})
            assert [rewards[a] for a in names] == info["agent_reward"][i].tolist(), (k, i)
            assert (te[names[0]], tr[names[0]]) == (term[i], trunc[i]), (k, i)
            final = info["final_obs"][i] if term[i] or trunc[i] else obs[i]
            assert [final[j].tolist() for j in range(2)] == [one[a].tolist() for a in names], (k, i)
            if term[i] or trunc[i]:
                ends += 1
                one, infos = env.reset()  # the vector env's world draws on from its own generator
                assert [obs[i, j].tolist() for j in range(2)] == [one[a].tolist() for a in names], (k, i)
    assert ends >= worlds  # the restarts were compared too


def test_autoreset_never_mixes_two_episodes_in_a_teams_stacked_observation() -> None:
    """The nonmarkov id through gym.make_vec: two agents a team (one slow), [current, previous] each. A
    continuing world's previous half is its last current half; a restarted world's returned observation is
    its start (the previous half the start again), final_obs the ended game's last, with its own past."""
    env = gym.make_vec(NONMARKOV, num_envs=6, max_steps=9)
    start, info0 = env.reset(seed=5)
    assert start.shape == (6, 2, 28) and info0["action_mask"].shape == (6, 2, 9)
    d = start.shape[-1] // 2
    np.testing.assert_array_equal(start[..., d:], start[..., :d])
    prev, t, ends = start, np.zeros(6, np.int64), 0
    rng = np.random.default_rng(5)
    for _ in range(60):
        obs, _, term, trunc, info = env.step(rng.integers(0, 9, (6, 2)))
        done, cont = term | trunc, ~(term | trunc)
        np.testing.assert_array_equal(obs[cont, :, d:], prev[cont, :, :d])
        np.testing.assert_array_equal(info["t"][cont], t[cont] + 1)
        if done.any():
            ends += int(done.sum())
            assert (info["_final_obs"] == done).all() and (info["_final_info"] == done).all()
            np.testing.assert_array_equal(info["final_obs"][done][..., d:], prev[done][..., :d])
            np.testing.assert_array_equal(info["final_info"]["t"][done], t[done] + 1)
            np.testing.assert_array_equal(obs[done][..., d:], obs[done][..., :d])  # a start: no past yet
            assert (info["t"][done] == 0).all()
        prev, t = obs, info["t"]
    assert ends >= 6


def test_every_world_truncates_at_the_step_limit_and_restarts_in_the_same_step() -> None:
    env = gym.make_vec(ADVANCED, num_envs=6, max_steps=5)
    first, info0 = env.reset(seed=0)
    nothing = np.full(6, env.world_spec.action_names.index("nothing"))
    for t in range(1, 6):
        obs, _, term, trunc, info = env.step(nothing)
        assert not term.any() and trunc.all() == (t == 5) and not (trunc.any() and t < 5)
    assert (info["final_info"]["t"] == 5).all() and (info["t"] == 0).all()
    assert (info["final_info"]["outcome"] == "truncated").all()
    np.testing.assert_array_equal(obs, first)
    np.testing.assert_array_equal(info["action_mask"], info0["action_mask"])
