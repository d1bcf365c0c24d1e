"""tracelab.envs.vector_env.GridWarVectorEnv: gymnasium's vector API, same-step autoreset (against gymnasium's own
SyncVectorEnv of the single env), the two backends against each other, and the trace per episode."""
from __future__ import annotations

import warnings
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from gymnasium.wrappers.vector import RecordEpisodeStatistics

from tracelab.envs.sinks import MemorySink
from tracelab.envs.vector_env import GridWarVectorEnv
from tracelab.game.scenario import NOTHING, Scenario, builtin_scenario

BACKENDS = ("rules", "reference")


def short(name: str, max_steps: int = 12) -> Scenario:
    """A built-in scenario with a short step limit, so episodes end often (by truncation too)."""
    return replace(builtin_scenario(name), max_steps=max_steps)


def random_actions(env: VectorEnv, steps: int, seed: int = 0) -> np.ndarray:
    space = env.single_action_space
    n = space.n if isinstance(space, gym.spaces.Discrete) else int(space.nvec[0])
    return np.random.default_rng(seed).integers(0, n, (steps, *env.action_space.shape))


def test_vector_api() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = GridWarVectorEnv(5, "nonmarkov", backend="reference", stack_previous=True)
    assert isinstance(env, GridWarVectorEnv) and isinstance(env, VectorEnv)
    assert env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert env.single_observation_space.shape == (28,)  # with history
    assert env.observation_space == batch_space(env.single_observation_space, 5)
    assert env.action_space == batch_space(env.single_action_space, 5)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert info["action_mask"].shape == (5, 2, 9) and info["_action_mask"].all()
    for a in random_actions(env, 40):
        obs, rew, term, trunc, info = env.step(a)
        assert env.observation_space.contains(obs)
        assert rew.shape == term.shape == trunc.shape == (5,) and rew.dtype == np.float64
        assert all(info[f"_{k}"].shape == (5,) for k in info if not k.startswith("_"))
    with pytest.raises(ValueError):
        env.step(np.full((5, 2), 9))


@pytest.mark.parametrize("name", ("advanced", "nonmarkov"))
def test_rules_and_reference_backends_agree(name: str) -> None:
    scenario = short(name, 30)
    rules = GridWarVectorEnv(16, scenario, backend="rules")
    ref = GridWarVectorEnv(16, scenario, backend="reference")
    np.testing.assert_array_equal(rules.reset(seed=2)[0], ref.reset(seed=2)[0])
    for act in random_actions(rules, 150, seed=2):
        a, b = rules.step(act), ref.step(act)
        for x, y in zip(a[:4], b[:4]):
            np.testing.assert_array_equal(x, y)
        assert a[4].keys() == b[4].keys()
        for key in a[4]:
            if key != "final_info":
                np.testing.assert_array_equal(a[4][key], b[4][key], err_msg=key)


def test_same_seed_same_run_and_seed_lists() -> None:
    def run(seed: object) -> list:
        env = GridWarVectorEnv(8, short("advanced"), backend="reference")
        out = [env.reset(seed=seed)[0]]
        for act in random_actions(env, 60):
            out.extend(env.step(act)[:4])
        return out
    a, b, c = run(3), run(3), run(4)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not all(np.array_equal(x, y) for x, y in zip(a, c))
    d, e = run([1, 2, 3]), run([1, 2, 3])
    assert all(np.array_equal(x, y) for x, y in zip(d, e))


@pytest.mark.parametrize("backend", BACKENDS)
def test_autoreset_never_mixes_two_episodes(backend: str) -> None:
    """With history in the observation, a transition that mixed episodes would show it: after a reset
    the previous half must be the reset observation itself, never the last episode's."""
    scenario = short("nonmarkov", 9)
    env = GridWarVectorEnv(8, scenario, backend=backend, stack_previous=True)
    start, info0 = env.reset(seed=5)
    d = start.shape[1] // 2
    prev, t = start, np.zeros(8, np.int64)
    ends = 0
    for act in random_actions(env, 150, seed=5):
        obs, rew, term, trunc, info = env.step(act)
        done = term | trunc
        cont = ~done
        # a continuing world: its history half is the previous observation's current half
        np.testing.assert_array_equal(obs[cont, d:], prev[cont, :d])
        np.testing.assert_array_equal(info["t"][cont], t[cont] + 1)
        if done.any():
            ends += int(done.sum())
            assert (info["_final_obs"] == done).all() and (info["_final_info"] == done).all()
            final = info["final_obs"][done]
            np.testing.assert_array_equal(final[:, d:], prev[done, :d])  # the last transition's own past
            np.testing.assert_array_equal(info["final_info"]["t"][done], t[done] + 1)
            np.testing.assert_array_equal(obs[done], start[done])        # the new episode's first obs
            assert (info["t"][done] == 0).all() and (info["unsafe"][done] == 0).all()
            np.testing.assert_array_equal(info["action_mask"][done], info0["action_mask"][done])
            truncated = ~term[done] & (info["final_info"]["t"][done] == scenario.max_steps)
            np.testing.assert_array_equal(trunc[done], truncated)
        prev, t = obs, info["t"]
    assert ends > 20


@pytest.mark.parametrize("backend", BACKENDS)
def test_returned_arrays_are_not_changed_later(backend: str) -> None:
    """A replay buffer may keep what step() returned without copying it."""
    env = GridWarVectorEnv(8, short("advanced", 6), backend=backend)
    kept = [env.reset(seed=0)[0]]
    for act in random_actions(env, 40):
        obs, rew, term, trunc, info = env.step(act)
        kept += [obs, rew, term, trunc, info["action_mask"]]
    copies = [k.copy() for k in kept]
    env.reset()  # RuleSim.reset writes into its last observation array
    for act in random_actions(env, 40, seed=1):
        env.step(act)
    assert all(np.array_equal(a, b) for a, b in zip(kept, copies))


def test_truncation_of_every_world_at_the_step_limit() -> None:
    scenario = short("advanced", 5)
    env = GridWarVectorEnv(6, scenario, backend="rules")
    first, info0 = env.reset(seed=0)
    nothing = np.full(6, scenario.action_ids.index(NOTHING))
    for t in range(1, 6):
        obs, rew, term, trunc, info = env.step(nothing)
        assert not term.any() and trunc.all() == (t == 5) and not (trunc.any() and t < 5)
    assert (info["final_info"]["t"] == 5).all() and (info["t"] == 0).all()
    np.testing.assert_array_equal(obs, first)
    np.testing.assert_array_equal(info["action_mask"], info0["action_mask"])


def test_episode_statistics_wrapper_counts_same_step_episodes() -> None:
    env = RecordEpisodeStatistics(GridWarVectorEnv(4, short("advanced", 5), backend="reference"))
    env.reset(seed=0)
    for _ in range(5):
        *_, info = env.step(np.full(4, 8))
    assert (info["episode"]["l"] == 5).all()
    assert np.allclose(info["episode"]["r"], 5 * -2.0)


def test_trace_rows_are_per_episode() -> None:
    scenario = short("advanced", 7)
    sink = MemorySink()
    env = GridWarVectorEnv(4, scenario, backend="rules", trace_sink=sink)
    env.reset(seed=1)
    running = np.zeros(4)
    returns: list[list[float]] = [[] for _ in range(4)]  # finished episodes' returns, per world
    for act in random_actions(env, 30, seed=1):
        _, rew, term, trunc, _ = env.step(act)
        running += rew
        for w in np.flatnonzero(term | trunc):
            returns[w].append(running[w])
            running[w] = 0.0
    env.close()
    assert sink.closed
    begun = {b["episode"]: b["world"] for b in sink.begun}
    assert sorted(begun) == list(range(len(begun))) and len(begun) > 8
    ended = {e["episode"]: e for e in sink.ended}
    assert set(ended) == set(begun)  # closing ended the open episodes
    assert sum(e["outcome"] == "aborted" for e in sink.ended) == 4
    for e, world in begun.items():
        rows, steps = sink.rows(e), sink.steps(e)
        assert (rows["world"] == world).all() and (steps["world"] == world).all()
        n = ended[e]["steps"]
        assert set(rows["t"].tolist()) == set(range(n + 1))  # local steps 0..n; 0: the start rows
        assert len(set(rows["world_episode"].tolist())) == 1  # one simulator episode
        np.testing.assert_array_equal(steps["t"], np.arange(1, n + 1))
    for w in range(4):
        finished = [ended[e]["rewards"]["red"] for e in sorted(ended)
                    if begun[e] == w and ended[e]["outcome"] != "aborted"]
        assert finished == pytest.approx(returns[w])
