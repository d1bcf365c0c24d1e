"""gymnasium's toy-text games written as rules (rules/toytext/) against gymnasium's own implementation:
the same seed and actions give the same observations, rewards, terminated and truncated at every step."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.toy_text.frozen_lake import generate_random_map
from gymnasium.utils.env_checker import check_env

import tracelab.envs  # noqa: F401  (registers tracelab/FrozenLake-v1)

STEPS = 10_000  # random-action steps per variant, across episodes


def run_side_by_side(ours: gym.Env, theirs: gym.Env, steps: int, seed: int, *, cut: int = 10**9,
                     masked: float = 0.0, watch=None) -> int:
    """Step both envs with the same random actions until `steps` steps were compared; each new seed
    starts an episode with reset(seed=...), and every other episode continues the stream (reset()).
    An episode is also cut after `cut` steps (a game without a step limit). With `masked` > 0 that share
    of actions is drawn among those gymnasium's info["action_mask"] allows (which is then compared too),
    so that rare events happen often. `watch(before, after)` sees gymnasium's states around each step.
    Returns the number of episodes."""
    rng = np.random.default_rng(seed)
    n_actions = theirs.action_space.n
    done, episodes, length = True, 0, 0
    for n in range(steps):
        if done or length >= cut:
            s = None if episodes % 2 else seed + episodes
            got, want = ours.reset(seed=s), theirs.reset(seed=s)
            assert got[0] == want[0], f"reset {episodes} (seed {s}): obs {got[0]} != {want[0]}"
            _same_mask(got[1], want[1], f"reset {episodes}")
            info, episodes, length = want[1], episodes + 1, 0
        if masked and rng.random() < masked:
            a = int(rng.choice(np.flatnonzero(info["action_mask"])))
        else:
            a = int(rng.integers(n_actions))
        before = theirs.unwrapped.s
        got, want = ours.step(a), theirs.step(a)
        length += 1
        assert got[:4] == want[:4], f"step {n} (episode {episodes}, action {a}): {got[:4]} != {want[:4]}"
        _same_mask(got[4], want[4], f"step {n}")
        if watch is not None:
            watch(before, want[0])
        info, done = want[4], got[2] or got[3]
    return episodes


def _same_mask(got: dict, want: dict, where: str) -> None:
    if "action_mask" in want:
        assert got["action_mask"].tolist() == want["action_mask"].tolist(), \
            f"{where}: action_mask {got['action_mask']} != {want['action_mask']}"


CUSTOM = ["SFFHF", "FHFFS", "FFHFF", "HFFFG"]  # not square, two start cells (drawn as gymnasium does)

VARIANTS = {
    "4x4-slippery": {},
    "4x4-dry": {"is_slippery": False},
    "8x8-slippery": {"map_name": "8x8"},
    "8x8-dry": {"map_name": "8x8", "is_slippery": False},
    "custom-rate-schedule": {"desc": CUSTOM, "success_rate": 0.6, "reward_schedule": (5, -2, 0.5)},
    "generated": {"desc": generate_random_map(size=6, p=0.7, seed=11), "success_rate": 0.8},
}


@pytest.mark.parametrize("desc", [np.asarray(CUSTOM, dtype="c"), [list(row) for row in CUSTOM]],
                         ids=["numpy-bytes", "lists-of-characters"])
def test_frozen_lake_takes_desc_in_gymnasiums_other_forms(desc) -> None:
    ours, theirs = gym.make("tracelab/FrozenLake-v1", desc=desc), gym.make("FrozenLake-v1", desc=desc)
    assert ours.observation_space == theirs.observation_space == gym.spaces.Discrete(20)
    run_side_by_side(ours, theirs, 1_000, seed=6)


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_frozen_lake_matches_gymnasium(variant: str) -> None:
    kwargs = VARIANTS[variant]
    ours = gym.make("tracelab/FrozenLake-v1", **kwargs)
    theirs = gym.make("FrozenLake-v1", **kwargs)
    assert ours.spec.max_episode_steps == theirs.spec.max_episode_steps == 100
    assert ours.observation_space == theirs.observation_space and ours.action_space == theirs.action_space
    episodes = run_side_by_side(ours, theirs, STEPS, seed=len(variant))
    assert episodes > 50  # many episodes, so many seeds and many ends


def test_frozen_lake_8x8_id_has_gymnasiums_limit() -> None:
    ours, theirs = gym.make("tracelab/FrozenLake8x8-v1"), gym.make("FrozenLake8x8-v1")
    assert ours.spec.max_episode_steps == theirs.spec.max_episode_steps == 200
    run_side_by_side(ours, theirs, 2_000, seed=3)


@pytest.mark.parametrize("env_id", ["tracelab/FrozenLake-v1", "tracelab/CliffWalking-v1", "tracelab/Taxi-v4"])
def test_toytext_envs_pass_gymnasiums_env_checker(env_id: str) -> None:
    check_env(gym.make(env_id, render_mode="ansi").unwrapped)


def test_frozen_lake_renders_its_map_as_text() -> None:
    env = gym.make("tracelab/FrozenLake-v1", render_mode="ansi")
    env.reset(seed=0)
    text = env.render()
    assert text.splitlines()[1:] == ["@FFF", "FHFH", "FFFH", "HFFG"]


@pytest.mark.parametrize("is_slippery", [False, True])
def test_cliff_walking_matches_gymnasium(is_slippery: bool) -> None:
    ours = gym.make("tracelab/CliffWalking-v1", is_slippery=is_slippery)
    theirs = gym.make("CliffWalking-v1", is_slippery=is_slippery)
    assert ours.spec.max_episode_steps is theirs.spec.max_episode_steps is None
    assert ours.observation_space == theirs.observation_space and ours.action_space == theirs.action_space
    # random walks seldom reach the goal: episodes are cut after 150 steps, so that many seeds are drawn
    assert run_side_by_side(ours, theirs, STEPS, seed=int(is_slippery), cut=150) > 50


def test_cliff_walking_slippery_id() -> None:
    ours, theirs = gym.make("tracelab/CliffWalkingSlippery-v1"), gym.make("CliffWalkingSlippery-v1")
    run_side_by_side(ours, theirs, 2_000, seed=9, cut=150)


TAXI_VARIANTS = {
    "dry": {},
    "rainy": {"is_rainy": True, "rainy_probability": 0.7},
    "fickle": {"fickle_passenger": True},
    "rainy-fickle": {"is_rainy": True, "fickle_passenger": True, "fickle_probability": 0.9},
}


@pytest.mark.parametrize("variant", list(TAXI_VARIANTS))
def test_taxi_matches_gymnasium(variant: str) -> None:
    kwargs = TAXI_VARIANTS[variant]
    ours, theirs = gym.make("tracelab/Taxi-v4", **kwargs), gym.make("Taxi-v4", **kwargs)
    assert ours.spec.max_episode_steps == theirs.spec.max_episode_steps == 200
    assert ours.observation_space == theirs.observation_space and ours.action_space == theirs.action_space
    decode = theirs.unwrapped.decode
    seen = {"pickups": 0, "dropoffs": 0, "new destinations": 0}

    def watch(before: int, after: int) -> None:
        (_, _, p0, d0), (_, _, p1, d1) = decode(before), decode(after)
        seen["pickups"] += p0 < 4 and p1 == 4
        seen["dropoffs"] += p0 == 4 and p1 < 4
        seen["new destinations"] += d0 != d1

    # 70% of the actions among the allowed ones, so that pickups, dropoffs and deliveries are frequent
    episodes = run_side_by_side(ours, theirs, STEPS, seed=len(variant), masked=0.7, watch=watch)
    assert episodes > 40 and seen["pickups"] > 50 and seen["dropoffs"] > 40, seen
    assert (seen["new destinations"] > 5) == kwargs.get("fickle_passenger", False), seen


@pytest.mark.parametrize("kernel", ["lanes", "counting"])
def test_a_kernel_asked_for_by_name_gives_the_same_games(kernel: str) -> None:
    """The fused one-call step (the counting kernel, the default) and the engine's own steps (any kernel
    named) read and draw alike."""
    ours = gym.make("tracelab/Taxi-v4", is_rainy=True, fickle_passenger=True, kernel=kernel)
    assert ours.unwrapped.world.engine.kernel == kernel
    run_side_by_side(ours, gym.make("Taxi-v4", is_rainy=True, fickle_passenger=True), 3_000, seed=4, masked=0.7)


def test_bench_toytext_quick(capsys: pytest.CaptureFixture) -> None:
    """`tracelab bench toytext` measures both sides of each game (figures in docs/worlds.md, not asserted)."""
    import json

    from tracelab.cli import main
    assert main(["bench", "toytext", "--quick", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert [g["game"] for g in r["games"]] == ["FrozenLake 4x4", "FrozenLake 8x8 dry", "CliffWalking", "Taxi"]
    for g in r["games"]:
        assert g["tracelab"]["steps_per_s"]["median"] > 0 and g["gymnasium"]["steps_per_s"]["median"] > 0
        assert g["goal_met"] == (g["ratio"] >= r["goal_ratio"])
        # traced and untraced in turn, also per CPU second (the writer's thread included)
        assert g["traced"]["steps_per_cpu_s"]["median"] > 0 and g["tracelab"]["steps_per_cpu_s"]["median"] > 0
        assert g["traced_cpu_ratio"] == pytest.approx(g["traced"]["steps_per_cpu_s"]["median"]
                                                      / g["tracelab"]["steps_per_cpu_s"]["median"])


def test_rgb_array_draws_the_declared_board() -> None:
    env = gym.make("tracelab/FrozenLake-v1", render_mode="rgb_array", is_slippery=False)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (4 * 24, 4 * 24, 3) and frame.dtype == np.uint8
    centre = lambda img, r, c: tuple(img[r * 24 + 12, c * 24 + 12])  # noqa: E731
    assert centre(frame, 0, 0) == (0xD6, 0x27, 0x28)          # the player's disc on the start cell
    assert centre(frame, 1, 1) == (0x1F, 0x3B, 0x73)          # a hole
    env.step(2)  # right
    after = env.render()
    assert centre(after, 0, 0) == (0xCF, 0xE8, 0xF5) and centre(after, 0, 1) == (0xD6, 0x27, 0x28)
    assert (env.render() == after).all()  # the same state, the same bytes


def test_a_traced_world_plays_the_same_and_logs_why_the_agent_moved() -> None:
    """With the engine's change log on (what tracing into the store will read), the fused step pauses for
    trace room and goes on: the game is the same, and the rows name the slip and action facts."""
    from tracelab.engine import CAUSE_EXTERNAL, CAUSE_RULE
    from tracelab.envs.declared.gym_env import DeclaredEnv
    from tracelab.envs.declared.toytext import spec_path
    from tracelab.envs.declared.world import DeclaredWorld

    traced = DeclaredEnv(spec_path("frozen_lake.toml"))
    traced.world = DeclaredWorld(traced.world_spec, trace=True)
    run_side_by_side(traced, gym.make("FrozenLake-v1").unwrapped, 3_000, seed=2)
    eng = traced.world.engine
    rows = eng.take_trace()
    assert len(rows["atom"]) > 3_000
    texts = {eng.atom_text(int(a)) for a in rows["atom"][rows["cause_kind"] == CAUSE_EXTERNAL]}
    assert {"slip(cw)", "slip(straight)", "slip(ccw)", "pressed(left)", "pressed(up)"} <= texts
    moved = rows["atom"][rows["cause_kind"] == CAUSE_RULE]
    assert "at(c0_1)" in {eng.atom_text(int(a)) for a in moved}


@pytest.mark.parametrize("spec, kwargs", [("frozen_lake.toml", {}), ("cliff_walking.toml", {}),
                                          ("taxi.toml", {"fickle_passenger": True})])
def test_the_toytext_programs_have_no_warnings(spec: str, kwargs: dict) -> None:
    """Predicates only the env sets (pressed, slip, redirect) are known to be set: no "never set" (without
    a fickle passenger, Taxi's fickle and redirect atoms are indeed never set, and it says so)."""
    from tracelab.envs.declared.spec import load_spec
    from tracelab.envs.declared.toytext import spec_path
    assert load_spec(spec_path(spec), **kwargs).program.warnings == []
