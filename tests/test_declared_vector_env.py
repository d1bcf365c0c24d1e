"""The vector env of a declared world (tracelab/envs/declared/vector_env.py): every world, across its
resets, equals gymnasium's own game stepped with the same seed and actions (gymnasium's SyncVectorEnv with
SAME_STEP autoreset, final observations and infos included) and a single DeclaredEnv; its API; and the
engine's restore from another world's state that its resets use."""
from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.toy_text.frozen_lake import generate_random_map
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from gymnasium.wrappers.vector import RecordEpisodeStatistics

from tracelab.engine import Engine, parse_program
from tracelab.envs import make_env, make_vec_env
from tracelab.envs.declared.toytext import spec_path
from tracelab.envs.declared.vector_env import DeclaredVectorEnv
from test_env_spec import SPEC, write_world

# (worlds, steps): 16 worlds run on the counting kernel (one compiled call with the reads), 64 on the lanes
# kernel (the engine's step); over 10,000 world-steps a game either way
SIZES = [(16, 700), (64, 250)]

GAMES = [  # (gymnasium's id, tracelab's id, keyword arguments of both)
    ("FrozenLake-v1", "tracelab/FrozenLake-v1", {"is_slippery": True}),
    ("FrozenLake-v1", "tracelab/FrozenLake-v1", {"desc": generate_random_map(6, seed=4), "is_slippery": True}),
    ("CliffWalking-v1", "tracelab/CliffWalking-v1", {"max_episode_steps": 60}),  # random walks rarely end
    ("CliffWalking-v1", "tracelab/CliffWalking-v1", {"is_slippery": True, "max_episode_steps": 60}),
    ("Taxi-v4", "tracelab/Taxi-v4", {}),
    ("Taxi-v4", "tracelab/Taxi-v4", {"is_rainy": True}),
]


def _theirs(gym_id: str, kwargs: dict, n: int) -> VectorEnv:
    return gym.make_vec(gym_id, num_envs=n, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP}, **kwargs)


def _same_info(ours: dict, theirs: dict, step: int) -> None:
    if "action_mask" in theirs:
        np.testing.assert_array_equal(ours["action_mask"], theirs["action_mask"], err_msg=f"step {step}")
        np.testing.assert_array_equal(ours["_action_mask"], theirs["_action_mask"])
    none = np.zeros(len(ours["t"]), bool)
    np.testing.assert_array_equal(ours.get("_final_obs", none), theirs.get("_final_obs", none), err_msg=f"step {step}")
    if "_final_obs" in theirs:
        ended = theirs["_final_obs"]
        np.testing.assert_array_equal(ours["final_obs"][ended], theirs["final_obs"][ended].astype(np.int64))
        final_mask = theirs["final_info"].get("action_mask")
        if final_mask is not None:
            np.testing.assert_array_equal(ours["final_info"]["action_mask"][ended], final_mask[ended])
        np.testing.assert_array_equal(ours["final_info"]["_t"], ended)


@pytest.mark.parametrize("worlds, steps", SIZES, ids=["counting", "lanes"])
@pytest.mark.parametrize("gym_id, our_id, kwargs", GAMES, ids=lambda v: str(v)[:24] if isinstance(v, str) else None)
def test_each_world_equals_gymnasiums_own_game(gym_id: str, our_id: str, kwargs: dict, worlds: int,
                                               steps: int) -> None:
    """Observations, rewards, terminated, truncated, action masks and the final observations of worlds that
    ended, at every step of the worlds seeded 7, 8, ... (SyncVectorEnv's seeding), across their resets."""
    ours = gym.make_vec(our_id, num_envs=worlds, vectorization_mode="vector_entry_point", **kwargs)
    theirs = _theirs(gym_id, kwargs, worlds)
    assert isinstance(ours, DeclaredVectorEnv)
    assert ours.worlds.kernel == ("lanes" if worlds >= 64 else "counting")
    obs, info = ours.reset(seed=7)
    their_obs, their_info = theirs.reset(seed=7)
    np.testing.assert_array_equal(obs, their_obs)
    if "action_mask" in their_info:
        np.testing.assert_array_equal(info["action_mask"], their_info["action_mask"])
    rng = np.random.default_rng(1)
    n = ours.single_action_space.n
    ends = 0
    for step in range(steps):
        actions = rng.integers(0, n, worlds)
        mine, other = ours.step(actions), theirs.step(actions)
        for k, name in enumerate(("obs", "reward", "terminated", "truncated")):
            np.testing.assert_array_equal(mine[k], other[k], err_msg=f"{name} at step {step}")
        _same_info(mine[4], other[4], step)
        ends += int((mine[2] | mine[3]).sum())
    assert ends >= worlds  # the worlds did restart (every game's episodes end under random actions)


@pytest.mark.parametrize("in_blocks", [True, False], ids=["numbers-in-blocks", "call-by-call"])
def test_each_world_equals_a_single_declared_env(in_blocks: bool) -> None:
    """World i of the vector env and a DeclaredEnv reset with seed[i] (a list of seeds) take the same
    observations, rewards and ends; after an end, the DeclaredEnv resets without a seed, as the world does.
    Both ways of drawing: random() numbers read 64 at a time (every draw of the toy-text games is one), and
    call by call (what a spec with a `choice` draw or per-step weights uses)."""
    seeds = [101, 5, 77, 3]
    spec = spec_path("frozen_lake.toml")
    vec = make_vec_env(spec, len(seeds), max_episode_steps=20)
    assert vec.worlds._only_uniforms
    vec.worlds._only_uniforms = in_blocks
    singles = [make_env(spec) for _ in seeds]
    obs, _ = vec.reset(seed=seeds)
    assert (vec.worlds.uniforms is not None) == in_blocks
    assert obs.tolist() == [e.reset(seed=s)[0] for e, s in zip(singles, seeds)]
    rng = np.random.default_rng(2)
    for step in range(3000):
        actions = rng.integers(0, 4, len(seeds))
        obs, reward, terminated, truncated, info = vec.step(actions)
        for i, env in enumerate(singles):
            o, r, te, _, _ = env.step(int(actions[i]))
            tr = env.world.steps >= 20
            assert (r, te, tr) == (reward[i], terminated[i], truncated[i]), (step, i)
            if te or tr:
                assert info["final_obs"][i] == o and info["t"][i] == 0
                o, _ = env.reset()
            assert obs[i] == o, (step, i)


@pytest.mark.parametrize("space", ["Box", "MultiDiscrete", "Dict"])
@pytest.mark.parametrize("worlds", [3, 64])
def test_other_spaces_fuzzy_bounds_and_masks_world_by_world(tmp_path: Path, space: str, worlds: int) -> None:
    """test_env_spec's corridor (a Box of one-hot cells and a fuzzy atom's bounds, a scaled reward, a
    mask, a step limit; the fuzzy atom keeps even 64 worlds on the counting kernel) and its other
    spaces: each world equals a DeclaredEnv given the same actions."""
    spec = SPEC
    if space != "Box":
        head, rest = SPEC.split("[observation]")
        parts = ('[[observation.parts]]\nname = "p0"\nread = "index"\natom = "at(C)"\nover = "cells"\n'
                 + ('[[observation.parts]]\nname = "p1"\nread = "index"\natoms = ["bot(robo)", "over(w)"]\n'
                    if space == "MultiDiscrete" else
                    '[[observation.parts]]\nname = "p1"\nread = "lower"\natoms = ["energy(robo)"]\n'))
        spec = head + f'[observation]\nspace = "{space}"\n' + parts + rest[rest.index("[reward]"):]
    path = write_world(tmp_path, spec)
    vec = make_vec_env(path, worlds)
    assert vec.worlds.kernel == "counting"
    singles = [make_env(path) for _ in range(worlds)]
    obs, info = vec.reset(seed=0)
    rng = np.random.default_rng(3)
    starts = [e.reset(seed=i) for i, e in enumerate(singles)]
    for step in range(40):
        for i, (o, inf) in enumerate(starts):
            mine = {k: v[i] for k, v in obs.items()} if space == "Dict" else obs[i]
            theirs = o
            if space == "Dict":
                assert mine.keys() == theirs.keys() and all(np.array_equal(mine[k], theirs[k]) for k in mine)
            else:
                np.testing.assert_array_equal(mine, theirs, err_msg=f"step {step}, world {i}")
            np.testing.assert_array_equal(info["action_mask"][i], inf["action_mask"])
        assert vec.observation_space.contains(obs)
        actions = rng.integers(0, 3, worlds)
        obs, reward, terminated, truncated, info = vec.step(actions)
        starts = []
        for i, env in enumerate(singles):
            o, r, te, tr, inf = env.step(int(actions[i]))
            assert (r, te, tr) == (reward[i], terminated[i], truncated[i]), (step, i)
            if te or tr:
                o, inf = env.reset()
            starts.append((o, inf))


def test_vector_api() -> None:
    env = make_vec_env(spec_path("taxi.toml"), 5)
    assert env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert env.observation_space == batch_space(gym.spaces.Discrete(500), 5)
    assert env.action_space == batch_space(gym.spaces.Discrete(6), 5)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert info["action_mask"].shape == (5, 6) and info["action_mask"].dtype == np.int8 and info["_action_mask"].all()
    obs, reward, terminated, truncated, info = env.step(np.zeros(5, np.int64))
    assert reward.shape == terminated.shape == truncated.shape == (5,) and reward.dtype == np.float64
    assert terminated.dtype == np.bool_ and info["t"].tolist() == [1] * 5
    with pytest.raises(ValueError, match="actions must be 5 integers"):
        env.step(np.full(5, 6))
    with pytest.raises(ValueError, match="one seed per world"):
        env.reset(seed=[1, 2])
    # a reset with the same seed replays the same episodes
    a = [env.reset(seed=9)[0].tolist()] + [env.step(np.full(5, k % 6))[0].tolist() for k in range(30)]
    b = [env.reset(seed=9)[0].tolist()] + [env.step(np.full(5, k % 6))[0].tolist() for k in range(30)]
    assert a == b


def test_gymnasiums_vector_wrappers_read_it() -> None:
    """gymnasium 1.4 ships no vector env checker; its RecordEpisodeStatistics (which reads the autoreset
    mode) counts the episodes' returns and lengths as the env reports them."""
    env = RecordEpisodeStatistics(make_vec_env(spec_path("frozen_lake.toml"), 8, max_episode_steps=30))
    env.reset(seed=0)
    rng, lengths, t = np.random.default_rng(0), [], np.zeros(8, np.int64)
    for _ in range(200):
        _, _, terminated, truncated, info = env.step(rng.integers(0, 4, 8))
        t += 1
        done = terminated | truncated
        if done.any():
            np.testing.assert_array_equal(info["episode"]["l"][done], t[done])
            lengths.extend(t[done].tolist())
        t[done] = 0
    assert len(lengths) > 8 and max(lengths) <= 30


def test_a_random_fact_drawn_after_a_step_is_refused() -> None:
    """Taxi's fickle passenger is drawn after a step in some worlds only: not supported yet, said so."""
    with pytest.raises(ValueError, match="redirect.*drawn `after` a step"):
        make_vec_env(spec_path("taxi.toml"), 2, fickle_passenger=True)


PROGRAM = """
%timesteps persistent
next(w) <-1 step(w)
"""


@pytest.mark.parametrize("kernel", ["counting", "lanes"])
def test_engine_restore_from_another_worlds_state(kernel: str) -> None:
    """Engine.restore(snap, worlds, source=...): world 0 takes world 2's state in the snapshot (its atoms
    and its scheduled firings, shifted to the clock); world 1 keeps its own."""
    eng = Engine(parse_program(PROGRAM), worlds=3, kernel=kernel)
    step, nxt = eng.atom("step", "w"), eng.atom("next", "w")
    eng.add_fact(step, world=2)
    eng.step()
    snap = eng.snapshot()  # world 2: step(w) true, next(w) scheduled for the next step
    eng.run(3)
    both = np.array([step, nxt])
    assert eng.is_true(both).tolist() == [[False, False], [False, False], [True, True]]
    eng.restore(snap, np.array([0]), source=np.array([2]))
    assert eng.is_true(both).tolist() == [[True, False], [False, False], [True, True]]
    eng.step()  # world 2's firing, restored into world 0, lands there now
    assert eng.is_true(both).tolist() == [[True, True], [False, False], [True, True]]
    with pytest.raises(ValueError, match="one world of the snapshot"):
        eng.restore(snap, np.array([0, 1]), source=np.array([3, 0]))


def test_bench_toytext_times_the_vector_env(capsys: pytest.CaptureFixture) -> None:
    """`tracelab bench toytext --batch N` also times N worlds of each game in the vector env against
    gymnasium's SyncVectorEnv, in env-steps/s (figures in docs/worlds.md, not asserted)."""
    import json

    from tracelab.cli import main
    assert main(["bench", "toytext", "--quick", "--batch", "8", "--json"]) == 0
    v = json.loads(capsys.readouterr().out)["vector"]
    assert v["batch"] == 8 and v["goal_ratio"] == 5.0
    assert [g["game"] for g in v["games"]] == ["FrozenLake 4x4 slippery", "CliffWalking", "Taxi"]
    for g in v["games"]:
        assert g["tracelab"]["median"] > 0 and g["gymnasium"]["median"] > 0
        assert g["goal_met"] == (g["ratio"] >= 5.0)


CHAIN = """
%timesteps persistent
b(x) <-1 a(x)
c(x) <-! b(x), ~a(x)
a(x):[0,0] <-1 c(x)
"""


def test_restore_from_other_worlds_alike_on_both_kernels() -> None:
    """The same facts, snapshot, restores from other worlds (sources drawn at random) and steps on the
    counting and the lanes kernel: the same bounds and the same last causes (what a why tree reads) in
    every world at every step."""
    rng = np.random.default_rng(5)
    engines = [Engine(parse_program(CHAIN), worlds=70, kernel=k) for k in ("counting", "lanes")]
    a = [e.atom("a", "x") for e in engines][0]
    plan = [rng.random(70) < 0.3 for _ in range(12)]
    sources = [rng.integers(0, 70, 9) for _ in range(4)]
    targets = [rng.choice(70, 9, replace=False) for _ in range(4)]
    seen = []
    for eng in engines:
        states = []
        snap = None
        for t, on in enumerate(plan):
            eng.add_facts(np.full(int(on.sum()), a), 1.0, 1.0, np.flatnonzero(on))
            eng.step()
            if t == 3:
                snap = eng.snapshot()
            if t >= 6 and t - 6 < len(sources):
                eng.restore(snap, targets[t - 6], source=sources[t - 6])
            states.append((eng.lower.copy(), eng.upper.copy(), eng._state.last_cause.copy()))
        seen.append(states)
    for t, (mine, theirs) in enumerate(zip(*seen)):
        for name, x, y in zip(("lower", "upper", "last cause"), mine, theirs):
            np.testing.assert_array_equal(x, y, err_msg=f"{name} at step {t}")


@pytest.mark.parametrize("kernel", ["counting", "lanes"])
def test_gridwar_worlds_equal_single_declared_envs(kernel: str) -> None:
    """GridWar's advanced spec (a Box of seven parts, two `nearest`; three draws a step, taken for all
    worlds at once; one start outcome, restored world by world from its own snapshot world): each world of
    the vector env equals a DeclaredEnv reset with seed + i, given the same actions, across resets."""
    from tracelab import RULES_DIR
    spec, n, seed = RULES_DIR / "gridworld" / "war.toml", 3, 11
    vec = make_vec_env(spec, n, kernel=kernel, advanced=True)
    assert vec.worlds.kernel == kernel
    singles = [make_env(spec, advanced=True) for _ in range(n)]
    obs, info = vec.reset(seed=seed)
    assert vec.worlds.uniforms is not None  # every draw one random(): a step's three taken at once
    for i, env in enumerate(singles):
        o, inf = env.reset(seed=seed + i)
        np.testing.assert_array_equal(obs[i], o)
        np.testing.assert_array_equal(info["action_mask"][i], inf["action_mask"])
    rng, ends = np.random.default_rng(4), 0
    for step in range(250):
        actions = rng.integers(0, 9, n)
        obs, reward, terminated, truncated, info = vec.step(actions)
        for i, env in enumerate(singles):
            o, r, te, tr, inf = env.step(int(actions[i]))
            assert (r, te, tr) == (reward[i], terminated[i], truncated[i]), (step, i)
            if te or tr:
                np.testing.assert_array_equal(info["final_obs"][i], o)
                o, inf = env.reset()
                ends += 1
            np.testing.assert_array_equal(obs[i], o, err_msg=f"step {step}, world {i}")
            np.testing.assert_array_equal(info["action_mask"][i], inf["action_mask"])
    assert ends >= n  # the restarts were compared too


def test_gridwar_team_worlds_equal_single_declared_worlds() -> None:
    """Several agents a world (war.toml's base game, 2 a team): DeclaredWorlds.step takes one action per
    world and agent (-1: none), and each world then equals a DeclaredWorld given the same actions and a
    generator of the same seed: every agent's observation and reward, the ends, across restarts."""
    from tracelab import RULES_DIR
    from tracelab.envs.declared.spec import load_spec
    from tracelab.envs.declared.vector_world import DeclaredWorlds
    from tracelab.envs.declared.world import DeclaredWorld
    spec = load_spec(RULES_DIR / "gridworld" / "war.toml", agents_per_team=2)
    n, seed = 3, 5
    batch = DeclaredWorlds(spec, n, kernel="counting")
    batch.use_generators([np.random.default_rng(seed + i) for i in range(n)])
    batch.reset(np.arange(n))
    singles = [DeclaredWorld(spec, kernel="counting") for _ in range(n)]
    rngs = [np.random.default_rng(seed + i) for i in range(n)]
    for world, r in zip(singles, rngs):
        world.reset(r)
    rng, ends = np.random.default_rng(8), 0
    for step in range(150):
        actions = rng.integers(-1, batch.n_actions, (n, 2))
        batch.step(actions)
        done = batch.terminated() | batch.truncated(None)
        for i, world in enumerate(singles):
            world.step(actions[i], rngs[i])
            for agent in range(2):
                np.testing.assert_array_equal(batch.observations(agent)[i], world.observation(agent),
                                              err_msg=f"step {step}, world {i}, agent {agent}")
                assert batch.rewards(agent)[i] == world.last_rewards[agent], (step, i, agent)
            assert done[i] == (world.terminated() or world.truncated()), (step, i)
            if done[i]:
                world.reset(rngs[i])
                ends += 1
        batch.reset(np.flatnonzero(done))
    assert ends >= n  # restarts compared too
