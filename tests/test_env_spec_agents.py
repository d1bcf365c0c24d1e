"""A spec with several agents: `Agent` stands for each in actions, observations, rewards and ends, and
the world is a PettingZoo ParallelEnv that passes PettingZoo's own API test."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from tracelab.envs import make_env
from tracelab.envs.declared.parallel_env import DeclaredParallelEnv

RULES = """\
%mode override
%closed dest
snap:     was(A, C) <-1 at(A, C)
snap_off: was(A, C):[0,0] <-1 was(A, C), at(A, C):[0,0]
clr_dest: dest(A, C):[0,0] <-1 dest(A, C)
clr_can:  can(A, D):[0,0] <-1 can(A, D)
step_w:   dest(A, E) <-! was(A, C), go(A, west), west(C, E)
step_e:   dest(A, E) <-! was(A, C), go(A, east), east(C, E)
arrive:   at(A, E) <-! dest(A, E)
leave:    at(A, C):[0,0] <-! was(A, C), dest(A, E), ~dest(A, C)
home:     home(A) <-! at(A, C), door(C)
both:     over(game) <-! home(ann), home(bob)
can_w:    can(A, west) <-! at(A, C), west(C, E)
can_e:    can(A, east) <-! at(A, C), east(C, E)
can_rest: can(A, rest) <-! at(A, C)
"""

SPEC = """\
[env]
rules = ["pair.rules"]

[board]
rows = ["....D"]
legend = { D = ["door"] }
neighbours = { west = [0, -1], east = [0, 1] }
edge = "none"

[agents]
names = ["ann", "bob"]
mask = "can(Agent, Action)"

[actions]
west = ["go(Agent, west)"]
east = ["go(Agent, east)"]
rest = []

[observation]
space = "Discrete"
[[observation.parts]]
name = "cell"
read = "index"
atom = "at(Agent, C)"
over = "cells"

[reward.table]
"home(Agent)" = 1

[end]
terminated = ["over(game)"]
max_steps = 30

[start]
facts = ["at(ann, c0_0)", "at(bob, c0_2)"]
"""


@pytest.fixture
def pair(tmp_path: Path) -> Path:
    (tmp_path / "pair.rules").write_text(RULES)
    (tmp_path / "pair.toml").write_text(SPEC)
    return tmp_path / "pair.toml"


def test_each_agent_acts_observes_and_is_rewarded_for_itself(pair: Path) -> None:
    env = DeclaredParallelEnv(pair, render_mode="ansi")
    obs, infos = env.reset(seed=0)
    assert obs == {"ann": 0, "bob": 2}
    assert infos["ann"]["action_mask"].tolist() == [0, 1, 1] and infos["bob"]["action_mask"].tolist() == [1, 1, 1]
    obs, rewards, terms, truncs, infos = env.step({"ann": 1, "bob": 1})
    assert obs == {"ann": 1, "bob": 3} and rewards == {"ann": 0.0, "bob": 0.0}
    obs, rewards, terms, truncs, infos = env.step({"bob": 1})  # ann, left out, does nothing
    assert obs == {"ann": 1, "bob": 4} and rewards == {"ann": 0.0, "bob": 1.0}
    assert infos["bob"]["action_mask"].tolist() == [1, 0, 1] and not any(terms.values())
    assert env.render().splitlines()[0] == "  (ann: -, bob: east)"
    for _ in range(3):
        obs, rewards, terms, truncs, infos = env.step({"ann": 1, "bob": 2})
    assert obs == {"ann": 4, "bob": 4} and rewards == {"ann": 1.0, "bob": 1.0}
    assert terms == {"ann": True, "bob": True} and env.agents == []


def test_it_passes_pettingzoos_parallel_api_test(pair: Path) -> None:
    parallel_api_test(DeclaredParallelEnv(pair), num_cycles=200)


def test_a_gymnasium_env_refuses_a_spec_of_several_agents(pair: Path) -> None:
    with pytest.raises(ValueError, match="a gymnasium Env plays one agent; this spec declares 2"):
        make_env(pair)


def test_seeded_runs_repeat(pair: Path) -> None:
    spec = pair.read_text().replace('facts = ["at(ann, c0_0)", ', 'facts = [')
    pair.write_text(spec + '[[start.choose]]\natom = "at(ann, C)"\nover = ["c0_0", "c0_1"]\n')
    env = DeclaredParallelEnv(pair)
    firsts = [env.reset(seed=s)[0]["ann"] for s in (3, 3, 4, 5, 6, 7, 8)]
    assert firsts[0] == firsts[1] and set(firsts) == {0, 1}
    assert np.random.default_rng(3).random() < 0.5 and firsts[0] == 0  # categorical: u < 1/2 takes value 0


def test_a_spec_of_one_agent_steps_as_a_pettingzoo_env_and_as_its_gymnasium_env() -> None:
    """DeclaredParallelEnv of a one-agent spec (war.toml at 1v1) steps (it failed: the world took its one
    agent's action as a number, and was handed a row of them), and gives what the gymnasium env gives."""
    from tracelab import RULES_DIR
    spec = RULES_DIR / "gridworld" / "war.toml"
    par, env = DeclaredParallelEnv(spec), make_env(spec)
    (agent,) = par.possible_agents
    obs, _ = par.reset(seed=3)
    o, _ = env.reset(seed=3)
    for a in [3, 3, 0, 2, 4, 1, 3, 0]:
        assert obs[agent].tolist() == o.tolist()
        obs, rewards, terminated, truncated, _ = par.step({agent: a})
        o, r, te, tr, _ = env.step(a)
        assert (rewards[agent], terminated[agent], truncated[agent]) == (r, te, tr)
        if te or tr:
            break
