"""The step contract (docs/envs.md): RefSim's StepResult arrays (the hand-written oracle's) are read-only
views of buffers that its next step or reset overwrites, unless it is built with copy=True; the declared
vector and PettingZoo envs hand out new arrays that no later step changes, as gymnasium's do."""
from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import tracelab.envs  # noqa: F401  (registers the ids)
from tracelab.envs.declared.gridwar import parallel_env
from tracelab.game.opponent import TeamPolicy, scripted_actions
from tracelab.game.refsim import RefSim
from tracelab.game.scenario import builtin_scenario
from tracelab.game.state import WINNER_NONE, StepResult

UP, DOWN, NOP = 0, 1, 8
FIELDS = [f.name for f in dataclasses.fields(StepResult)]


def short_base(max_steps: int = 50):
    return dataclasses.replace(builtin_scenario("base"), max_steps=max_steps)


def snapshot(r: StepResult) -> dict[str, np.ndarray]:
    return {name: getattr(r, name).copy() for name in FIELDS}


def test_a_step_result_is_overwritten_by_the_next_step() -> None:
    sim = RefSim(short_base(), 2, stack_previous=True)
    sim.reset(seed=0)
    first = sim.step(np.full((2, 1), UP), np.full((2, 1), NOP))
    before = snapshot(first)
    second = sim.step(np.full((2, 1), UP), np.full((2, 1), NOP))
    # the same buffers, now holding the second step
    assert np.shares_memory(first.positions, second.positions) and np.shares_memory(first.obs, second.obs)
    assert not np.array_equal(first.positions, before["positions"])  # red moved again
    assert not np.array_equal(first.obs, before["obs"])
    np.testing.assert_array_equal(first.t, before["t"] + 1)
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name), err_msg=name)


def test_step_buffers_are_read_only() -> None:
    sim = RefSim(short_base())
    obs = sim.reset(seed=0)
    r = sim.step([UP], [NOP])
    for a in (obs, r.obs, r.positions, r.reward, r.terminated, r.unsafe):
        with pytest.raises(ValueError):
            a[...] = 0
    # a result's copy is the caller's to change
    mine = r.copy()
    mine.positions[...] = -5
    assert (r.positions != -5).all()


def test_copy_true_gives_independent_arrays() -> None:
    sim = RefSim(short_base(3), 2, copy=True)
    obs0 = sim.reset(seed=0)
    kept = [(sim.step(np.full((2, 1), UP), np.full((2, 1), NOP)), None)]
    kept[0] = (kept[0][0], snapshot(kept[0][0]))
    for _ in range(4):  # past the step limit and a reset of the finished worlds
        r = sim.step(np.full((2, 1), UP), np.full((2, 1), NOP))
        kept.append((r, snapshot(r)))
        if r.done.any():
            sim.reset(worlds=r.done)
    assert obs0.flags.writeable and not np.shares_memory(obs0, sim.reset())
    for r, values in kept:
        for name in FIELDS:
            np.testing.assert_array_equal(getattr(r, name), values[name], err_msg=name)
    assert not np.shares_memory(kept[0][0].obs, kept[1][0].obs)
    assert not np.shares_memory(kept[0][0].positions, kept[1][0].positions)


def test_reset_with_a_mask_that_is_the_simulators_own_flag() -> None:
    # the mask passed to reset is the buffer reset clears: every reset world must be reset entirely
    sim = RefSim(short_base(2), 3)
    sim.reset(seed=0)
    sim.step(np.full((3, 1), UP), np.full((3, 1), NOP))
    r = sim.step(np.full((3, 1), UP), np.full((3, 1), NOP))
    assert r.truncated.all()
    sim.reset(worlds=r.truncated)
    assert (sim.state.t == 0).all() and not sim.state.truncated.any()
    assert (sim.state.winner == WINNER_NONE).all()
    start = RefSim(short_base(2), 3).reset()
    np.testing.assert_array_equal(r.obs, start)


def test_team_policy_draws_what_scripted_actions_draws() -> None:
    sc = builtin_scenario("advanced")
    sim = RefSim(sc, 5, seed=3)
    sim.reset()
    s = sim.state
    policy = TeamPolicy(sc, 5)
    a, b = np.random.default_rng(11), np.random.default_rng(11)
    for team in (0, 1, 1, 0):
        lean = policy(s.pos, s.alive, s.ammo, team, a, 0.6)
        np.testing.assert_array_equal(lean, scripted_actions(s.pos, s.alive, s.ammo, team, sc, b, 0.6))
    assert a.random() == b.random()  # the streams stayed aligned


def test_parallel_env_hands_out_nothing_a_later_step_changes() -> None:
    env = parallel_env("tracelab/GridWar-base-v0", agents_per_team=2, max_steps=6)
    up, down = env.world_spec.action_names.index("up"), env.world_spec.action_names.index("down")
    obs, infos = env.reset(seed=0)
    kept = list(obs.values()) + [i["action_mask"] for i in infos.values()]
    for _ in range(3):
        obs, _, _, _, infos = env.step({a: up for a in env.agents})
        kept += list(obs.values()) + [i["action_mask"] for i in infos.values()]
    copies = [k.copy() for k in kept]
    for _ in range(2):
        env.step({a: down for a in env.agents})
    assert all(np.array_equal(a, b) for a, b in zip(kept, copies))


@pytest.mark.parametrize("kwargs", [{}, {"agents_per_team": 2}], ids=["one agent", "a team"])
def test_vector_env_returns_new_arrays_that_no_later_step_changes(kwargs: dict) -> None:
    """gym.make_vec's observations, rewards, flags and infos (final ones too), with copy=True or False
    (SyncVectorEnv's switch; the declared env's observations are new arrays either way): a replay buffer
    may keep them without copying."""
    for copy in (True, False):
        env = gym.make_vec("tracelab/GridWar-base-v0", num_envs=4, max_steps=5, copy=copy, **kwargs)
        obs, info = env.reset(seed=0)
        kept = [obs, info["action_mask"], info["t"]]
        rng = np.random.default_rng(0)
        for _ in range(12):  # past two step limits: the ended worlds' final observations and infos too
            obs, reward, term, trunc, info = env.step(rng.integers(0, 5, env.action_space.shape))
            kept += [obs, reward, term, trunc, info["action_mask"], info["t"]]
            if "final_obs" in info:
                kept += [info["final_obs"], info["final_info"]["t"]]
        copies = [k.copy() for k in kept]
        env.reset(seed=1)
        for _ in range(8):
            env.step(rng.integers(0, 5, env.action_space.shape))
        assert all(np.array_equal(a, b) for a, b in zip(kept, copies)), copy
