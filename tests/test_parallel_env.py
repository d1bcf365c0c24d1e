"""tracelab.envs.parallel_env.GridWarParallelEnv: PettingZoo's parallel API test, agent names, per-agent rewards,
dead agents, the two backends against each other, and the trace of both teams' actions."""
from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test
from tracelab.engine import CAUSE_EXTERNAL

from tracelab.envs.parallel_env import GridWarParallelEnv
from tracelab.envs.sinks import MemorySink
from tracelab.game.scenario import NOTHING, RIGHT, SHOOT_UP, builtin_scenario

BACKENDS = ("rules", "reference")


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", ("base", "advanced", "nonmarkov"))
def test_parallel_api_test_is_clean(name: str, backend: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parallel_api_test(GridWarParallelEnv(name, backend=backend), num_cycles=400)


def test_agents_are_named_like_the_engines_nodes() -> None:
    env = GridWarParallelEnv("nonmarkov", backend="rules")
    assert env.possible_agents == ["red-agent-1", "red-agent-2", "blue-agent-1", "blue-agent-2"]
    for agent in env.possible_agents:
        env.sim.engine.atom("alive", agent)  # an existing node: no error
    obs, infos = env.reset(seed=0)
    assert env.agents == env.possible_agents
    np.testing.assert_array_equal(obs["red-agent-1"], obs["red-agent-2"])   # the team's observation
    np.testing.assert_array_equal(obs["blue-agent-1"][:4], [0, 7, 0, 7])    # blue sees itself first
    assert infos["red-agent-1"]["action_mask"].tolist() == [1, 0, 1, 0, 1, 1, 1, 1, 1]
    assert env.state_space.contains(env.state()) and env.state().shape == (28,)


@pytest.mark.parametrize("backend", BACKENDS)
def test_each_agent_gets_its_own_reward(backend: str) -> None:
    scenario = builtin_scenario("nonmarkov")
    ids = scenario.action_ids
    env = GridWarParallelEnv(scenario, backend=backend)
    env.reset(seed=0)
    # red-agent-1 moves off the map (its base is the bottom-right corner); everyone else waits
    _, rewards, _, _, infos = env.step({"red-agent-1": ids.index(RIGHT), "red-agent-2": ids.index(NOTHING),
                                        "blue-agent-1": ids.index(NOTHING), "blue-agent-2": ids.index(NOTHING)})
    assert rewards == {"red-agent-1": -200.0, "red-agent-2": -2.0, "blue-agent-1": -2.0, "blue-agent-2": -2.0}
    assert infos["red-agent-1"]["unsafe"] and not infos["red-agent-2"]["unsafe"]
    # an agent left out of the dict does nothing; the slow agents (agent 2) may not act on odd steps
    _, rewards, _, _, infos = env.step({"red-agent-1": ids.index(RIGHT)})
    assert rewards == {"red-agent-1": -200.0, "red-agent-2": 0.0, "blue-agent-1": -2.0, "blue-agent-2": 0.0}
    assert infos["red-agent-2"]["action_mask"].tolist() == [1, 0, 1, 0, 1, 1, 1, 1, 1]  # step 2: even


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_dead_agent_stays_until_the_game_ends_and_may_only_wait(backend: str) -> None:
    # blue-agent-1 stands three cells above red-agent-1, which shoots up: the bullet arrives at step 4
    scenario = replace(builtin_scenario("nonmarkov"), red_starts=((7, 0), (6, 0)), blue_starts=((7, 3), (0, 7)))
    ids = scenario.action_ids
    env = GridWarParallelEnv(scenario, backend=backend)
    env.reset(seed=0)
    wait = {a: ids.index(NOTHING) for a in env.possible_agents}
    obs, rewards, term, trunc, infos = env.step({**wait, "red-agent-1": ids.index(SHOOT_UP)})
    for _ in range(3):
        obs, rewards, term, trunc, infos = env.step(wait)
    assert rewards["red-agent-1"] == 400.0 - 2.0 and rewards["blue-agent-1"] == -200.0
    assert not infos["blue-agent-1"]["alive"] and not any(term.values())
    assert infos["blue-agent-1"]["action_mask"].tolist() == [0] * 8 + [1]
    assert env.agents == env.possible_agents
    np.testing.assert_array_equal(obs["red-agent-1"][4:6], [-1, -1])  # the dead opponent's sentinel
    # the dead agent's actions are ignored: its move neither counts nor costs
    _, rewards, _, _, infos = env.step({**wait, "blue-agent-1": ids.index(RIGHT)})
    assert rewards["blue-agent-1"] == 0.0 and not infos["blue-agent-1"]["unsafe"]


@pytest.mark.parametrize("name", ("advanced", "nonmarkov"))
def test_rules_and_reference_backends_agree(name: str) -> None:
    scenario = replace(builtin_scenario(name), max_steps=40)
    envs = [GridWarParallelEnv(scenario, backend=b, stack_previous=True) for b in BACKENDS]
    rng = np.random.default_rng(1)
    games = 0
    a, b = (e.reset(seed=1) for e in envs)
    for _ in range(400):
        assert a[0].keys() == b[0].keys()
        for agent in a[0]:
            np.testing.assert_array_equal(a[0][agent], b[0][agent])
            np.testing.assert_array_equal(a[-1][agent]["action_mask"], b[-1][agent]["action_mask"])
        if not envs[0].agents:
            assert not envs[1].agents
            games += 1
            a, b = (e.reset() for e in envs)
            continue
        actions = {agent: int(rng.integers(0, scenario.n_actions)) for agent in envs[0].agents}
        a, b = (e.step(actions) for e in envs)
        assert a[1:4] == b[1:4]  # rewards, terminations, truncations
    assert games >= 5


def test_game_end_ends_every_agent() -> None:
    scenario = replace(builtin_scenario("base"), red_starts=((1, 7),))
    env = GridWarParallelEnv(scenario, backend="rules")
    env.reset(seed=0)
    _, rewards, term, trunc, _ = env.step({"red-agent-1": scenario.action_ids.index(2)})  # onto the blue base
    assert term == {"red-agent-1": True, "blue-agent-1": True} and not any(trunc.values())
    assert rewards["red-agent-1"] == 248.0 and rewards["blue-agent-1"] == -252.0
    assert env.agents == []
    with pytest.raises(RuntimeError):
        env.step({})


def test_trace_has_both_teams_actions() -> None:
    sink = MemorySink()
    scenario = builtin_scenario("advanced")
    env = GridWarParallelEnv(scenario, backend="rules", trace_sink=sink)
    env.reset(seed=0)
    ids = scenario.action_ids
    env.step({"red-agent-1": ids.index(2), "blue-agent-1": ids.index(RIGHT)})
    env.close()
    rows = sink.rows(0)
    eng = env.sim.engine
    on = (rows["cause_kind"] == CAUSE_EXTERNAL) & (rows["t"] == 1) & (rows["new_lower"] == 1.0)
    assert sorted(eng.atom_text(int(a)) for a in rows["atom"][on]) == [
        "move(blue-agent-1,right)", "move(red-agent-1,left)"]
    np.testing.assert_array_equal(sink.steps(0)["actions"][0], [[2], [RIGHT]])
    assert sink.ended[0]["outcome"] == "aborted"
