"""GridWar's registered ids make the declared env over rules/gridworld/war.toml (issue 38, item 2): gym.make
and gym.make_vec pass gymnasium's checks, take the old RuleSim env's keyword arguments mapped onto the spec's
params (tracelab/envs/declared/gridwar.py) and refuse, in one line naming it, one the spec cannot honour;
rgb_array draws the spec's [board]. The step-by-step equality with RefSim is tests/test_gridwar_spec.py's."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tracelab.envs  # noqa: F401  (registers the ids)
from tracelab.envs.declared.gym_env import DeclaredEnv
from tracelab.envs.declared.render import CELL
from tracelab.envs.declared.vector_env import DeclaredVectorEnv
from tracelab.errors import UserError

from gridwar_refsim import RefGridWar

IDS = {"base": "tracelab/GridWar-base-v0", "advanced": "tracelab/GridWar-advanced-v0"}


@pytest.mark.parametrize("name", ["base", "advanced"])
def test_the_ids_make_the_declared_env_and_pass_gymnasiums_checker(name: str) -> None:
    for stack in (False, True):
        env = gym.make(IDS[name], stack_previous=stack)
        assert isinstance(env.unwrapped, DeclaredEnv) and env.unwrapped.world_spec.path.endswith("war.toml")
        assert env.observation_space.shape == ({"base": 4, "advanced": 7}[name] * (2 if stack else 1),)
        check_env(env.unwrapped, skip_render_check=True)


@pytest.mark.parametrize("name", ["base", "advanced"])
def test_a_seeded_episode_of_gym_make_equals_refsims(name: str) -> None:
    """The same seed and actions: RefSim's observations, masks, rewards and ends, to the end of a game."""
    env, ref = gym.make(IDS[name]), RefGridWar(name)
    (o1, i1), (o2, i2) = env.reset(seed=3), ref.reset(seed=3)
    rng = np.random.default_rng(3)
    for steps in range(1, 201):
        assert o1.tolist() == o2.tolist() and i1["action_mask"].tolist() == i2["action_mask"].tolist(), steps
        a = int(rng.choice(np.flatnonzero(i2["action_mask"])))
        o1, r1, te1, tr1, i1 = env.step(a)
        o2, r2, te2, tr2, i2 = ref.step(a)
        assert (r1, te1, tr1) == (r2, te2, tr2), steps
        if te1 or tr1:
            break
    assert te1 and i1["won"] == (i2["winner"] == 0), (steps, i1, i2)


def test_make_vec_steps_each_world_as_gym_make_seeded_seed_plus_i() -> None:
    venv = gym.make_vec(IDS["advanced"], num_envs=3, opponent_p=0.5)
    assert isinstance(venv, DeclaredVectorEnv)
    singles = [gym.make(IDS["advanced"], opponent_p=0.5) for _ in range(3)]
    obs, _ = venv.reset(seed=10)
    assert obs.tolist() == [e.reset(seed=10 + i)[0].tolist() for i, e in enumerate(singles)]
    for k in range(200):  # "nothing", until a world ends (the vector env then resets it in the step)
        obs, rew, term, _, info = venv.step(np.full(3, 8))
        steps = [e.step(8) for e in singles]
        assert rew.tolist() == [s[1] for s in steps] and term.tolist() == [s[2] for s in steps], k
        if term.any():
            break
        assert obs.tolist() == [s[0].tolist() for s in steps], k
    assert k > 5 and info["final_obs"][term].tolist() == [s[0].tolist() for s in steps if s[2]]


def test_gridwar_keyword_arguments_map_onto_the_specs_params() -> None:
    env = gym.make(IDS["base"], opponent_p=0.25, scenario="advanced", backend="rules", agents_per_team=1,
                   map="open", reward_scale=0.5)
    params = env.unwrapped.world_spec.params
    assert (params["p_toward"], params["advanced"], params["map"], params["reward_scale"]) == (0.25, True, "open", 0.5)
    assert env.action_space.n == 9


@pytest.mark.parametrize("kwargs, named", [
    ({"backend": "reference"}, "backend='reference' is not supported"),
    ({"trace_sink": object()}, "trace_sink=.* is not supported"),
    ({"scenario": "nonmarkov"}, "scenario='nonmarkov' is not supported"),
    ({"agents_per_team": 2}, "agents_per_team=2 is not supported by a gymnasium Env"),
    ({"colour": "red"}, "unknown keyword argument 'colour'"),
])
def test_a_keyword_the_spec_cannot_honour_is_refused_in_one_line_naming_it(kwargs: dict, named: str) -> None:
    with pytest.raises(ValueError, match=named) as e:
        gym.make(IDS["base"], **kwargs)
    assert "\n" not in str(e.value)


def test_the_nonmarkov_id_is_a_pettingzoo_env_not_a_gymnasium_one() -> None:
    with pytest.raises(UserError, match="GridWar-nonmarkov-v0: agents_per_team=2 .*parallel_env"):
        gym.make("tracelab/GridWar-nonmarkov-v0")


def test_rgb_array_draws_the_specs_board() -> None:
    """war.toml's [board] colours: mountains brown, the red base red, the blue base blue, top row first."""
    env = gym.make(IDS["base"], render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (8 * CELL, 8 * CELL, 3) and frame.dtype == np.uint8

    def centre(row: int, col: int) -> tuple[int, ...]:  # a tile's corner: the agents stand on the bases
        return tuple(frame[row * CELL + 2, col * CELL + 2])
    assert centre(2, 4) == (0x6b, 0x4f, 0x3a) and centre(7, 7) == (0xe6, 0x39, 0x46)
    assert centre(0, 0) == (0x3a, 0x86, 0xff)


def test_rgb_array_draws_the_pieces_where_they_stand() -> None:
    """[board] pieces in the frame: each agent a disc in its team's colour with a dark outline, on the cell
    its atLoc atom names; the frame follows the game (before: every frame of a game was the same picture)."""
    env = gym.make(IDS["base"], render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    rng = np.random.default_rng(0)
    for _ in range(40):
        env.step(int(rng.integers(env.action_space.n)))
        red = next(p for p in env.unwrapped.world.pieces_now() if p[1] == "red-agent-1")
        if red[2:4] != (7, 7) and red[4]:
            break
    else:
        pytest.fail("red never left its base alive in 40 steps")
    frame = env.render()
    row, col = red[2:4]
    outline = int(CELL * 0.42)  # a pixel of the ring, between the disc (0.36) and its edge (0.44)

    def at(f: np.ndarray, r: int, c: int, dy: int = 0) -> tuple[int, ...]:
        return tuple(int(v) for v in f[r * CELL + CELL // 2 - dy, c * CELL + CELL // 2])
    assert at(frame, row, col) == (0xe6, 0x39, 0x46) and at(frame, row, col, outline) == (25, 25, 25)
    assert at(first, 7, 7, outline) == (25, 25, 25) and at(frame, 7, 7, outline) == (0xe6, 0x39, 0x46)
    assert (first != frame).any()


def test_the_sb3_evaluations_of_a_gridwar_id_play_the_declared_env_against_eval_p() -> None:
    """TracelabCallback's evaluations (train/external_eval.py): GridWar's ids are declared targets, their
    games against the scripted opponent with the evaluation's opponent_p (the spec's p_toward)."""
    from tracelab.train.external_eval import DeclaredTarget, EvalSettings, eval_target
    target = eval_target(IDS["base"], {"map": "open"})
    assert isinstance(target, DeclaredTarget)
    evaluator = target.evaluator(None, lambda: 0, EvalSettings(games=2, traced=0, envs=2, level=0.1))
    try:
        assert evaluator.env.world_spec.params["p_toward"] == 0.1 and evaluator.env.world_spec.params["map"] == "open"
        assert target.outcome({"outcome": "win"}, True, False) == "win"
    finally:
        evaluator.close()
