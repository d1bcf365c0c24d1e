"""GridWar's PettingZoo env: the declared parallel env over its spec (tracelab.envs.declared.gridwar.
parallel_env), every red agent a player, the blue team the scripted opponent written as rules. PettingZoo's
parallel API test, agent names, the team's shared view, per-agent rewards and the game's end; RefSim's
equality step by step is tests/test_gridwar_spec.py's (play_teams)."""
from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from tracelab.envs.declared.gridwar import parallel_env
from tracelab.errors import UserError


@pytest.mark.parametrize("env_id, kwargs", [("tracelab/GridWar-base-v0", {"agents_per_team": 2}),
                                            ("tracelab/GridWar-advanced-v0", {}),
                                            ("tracelab/GridWar-nonmarkov-v0", {})])
def test_parallel_api_test_is_clean(env_id: str, kwargs: dict) -> None:
    parallel_api_test(parallel_env(env_id, **kwargs), num_cycles=200)


def test_agents_are_the_red_team_and_share_its_view() -> None:
    env = parallel_env("tracelab/GridWar-base-v0", agents_per_team=3, opponent_p=0.1)
    assert env.possible_agents == ["red-agent-1", "red-agent-2", "red-agent-3"]
    assert env.world_spec.params["p_toward"] == 0.1
    obs, infos = env.reset(seed=0)
    assert env.agents == env.possible_agents
    assert obs["red-agent-1"].tolist() == obs["red-agent-3"].tolist() == [7, 0] * 3 + [0, 7] * 3
    assert infos["red-agent-2"]["action_mask"].tolist() == [1, 0, 1, 0, 1]


def test_each_agent_gets_its_own_reward_and_a_slow_agent_waits_on_odd_steps() -> None:
    env = parallel_env("tracelab/GridWar-nonmarkov-v0")
    names = env.world_spec.action_names
    env.reset(seed=0)
    # red-agent-1 moves off the map (its base is the bottom-right corner); red-agent-2 waits
    _, rewards, _, _, _ = env.step({"red-agent-1": names.index("right"), "red-agent-2": names.index("nothing")})
    assert rewards == {"red-agent-1": -200.0, "red-agent-2": -2.0}
    # an agent left out of the dict does nothing: the slow agent 2 cannot act on step 1 and costs nothing
    _, rewards, _, _, infos = env.step({"red-agent-1": names.index("right")})
    assert rewards == {"red-agent-1": -200.0, "red-agent-2": 0.0}
    assert infos["red-agent-2"]["action_mask"].tolist() == [1, 0, 1, 0, 1, 1, 1, 1, 1]  # step 2: even


def test_game_end_ends_every_agent() -> None:
    env = parallel_env("tracelab/GridWar-base-v0", agents_per_team=2, max_steps=3)
    env.reset(seed=0)
    for _ in range(3):
        _, _, term, trunc, _ = env.step({})
    assert trunc == {"red-agent-1": True, "red-agent-2": True} and not any(term.values())
    assert env.agents == []
    with pytest.raises(RuntimeError):
        env.step({})


def test_not_a_gridwar_id_is_refused() -> None:
    with pytest.raises(UserError, match="'tracelab/FrozenLake-v1': not a GridWar id"):
        parallel_env("tracelab/FrozenLake-v1")


def test_rgb_array_frames_of_the_pettingzoo_env() -> None:
    env = parallel_env("tracelab/GridWar-base-v0", agents_per_team=2, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape[2] == 3
