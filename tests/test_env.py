"""tracelab.envs.gym_env.GridWarEnv: the gymnasium checks, seeding, the two backends against each other, the action
mask against what the simulator does, termination / truncation, and the trace streamed to a MemorySink."""
from __future__ import annotations

import warnings
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from tracelab.engine import CAUSE_EXTERNAL

from tracelab.envs.gym_env import ENV_IDS, GridWarEnv
from tracelab.envs.sinks import MemorySink, TraceSink
from tracelab.game.scenario import (
    LEFT,
    NOTHING,
    SHOOT_DOWN,
    SHOOT_UP,
    UP,
    builtin_scenario,
)
from tracelab.game.state import WINNER_RED

SCENARIOS = ("base", "advanced", "nonmarkov")
BACKENDS = ("rules", "reference")


def same(a: object, b: object) -> bool:
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return np.array_equal(np.asarray(a), np.asarray(b))


def run(env: GridWarEnv, seed: int, steps: int, action_seed: int = 0) -> list[tuple]:
    """A trajectory of random actions; reset (without a seed) whenever an episode ends."""
    rng = np.random.default_rng(action_seed)
    out = [env.reset(seed=seed)]
    for _ in range(steps):
        step = env.step(rng.integers(0, env.scenario.n_actions, env.action_space.shape or ()))
        out.append(step)
        if step[2] or step[3]:
            out.append(env.reset())
    return out


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", SCENARIOS)
def test_check_env_is_clean(name: str, backend: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for stack in (False, True):  # made through the registry: check_env also tries the render modes
            check_env(gym.make(ENV_IDS[name], backend=backend, stack_previous=stack).unwrapped)
        env = gym.make(ENV_IDS[name], backend=backend)  # with gymnasium's passive checker
        obs, info = env.reset(seed=1)
        assert env.observation_space.contains(obs)
        env.step(env.action_space.sample())


def test_spaces_follow_the_method() -> None:
    base, adv, nm = (GridWarEnv(n, backend="reference") for n in SCENARIOS)
    assert base.action_space == gym.spaces.Discrete(5) and base.observation_space.shape == (4,)
    assert adv.action_space == gym.spaces.Discrete(9) and adv.observation_space.shape == (7,)
    assert nm.action_space == gym.spaces.MultiDiscrete([9, 9]) and nm.observation_space.shape == (14,)
    assert gym.make(ENV_IDS["nonmarkov"]).observation_space.shape == (28,)  # registered with history
    obs, info = adv.reset(seed=0)
    np.testing.assert_array_equal(obs, [7, 0, 0, 7, 0, -1, -1])  # own, opponent, bullets: none yet
    assert info["action_mask"].dtype == np.int8 and info["action_mask"].shape == (9,)
    _, info = nm.reset(seed=0)
    assert info["action_mask"].shape == (2, 9)
    nm.action_space.sample(mask=tuple(info["action_mask"]))  # the documented way to sample with the mask


@pytest.mark.parametrize("backend", BACKENDS)
def test_same_seed_same_trajectory(backend: str) -> None:
    a = run(GridWarEnv("advanced", backend=backend), seed=7, steps=150)
    b = run(GridWarEnv("advanced", backend=backend), seed=7, steps=150)
    c = run(GridWarEnv("advanced", backend=backend), seed=8, steps=150)
    assert same(a, b)
    assert not same(a, c)  # the seed drives the opponent


@pytest.mark.parametrize("name", SCENARIOS)
def test_rules_and_reference_backends_agree(name: str) -> None:
    """The rule engine and the hand-written simulator: identical observations, rewards, flags and infos
    over several seeded episodes of random learner actions."""
    for seed in (0, 1):
        rules = run(GridWarEnv(name, backend="rules", stack_previous=True), seed=seed, steps=300, action_seed=seed)
        ref = run(GridWarEnv(name, backend="reference", stack_previous=True), seed=seed, steps=300,
                  action_seed=seed)
        assert len(rules) == len(ref)
        for i, (x, y) in enumerate(zip(rules, ref)):
            assert same(x, y), f"{name}, seed {seed}: entry {i} differs"
        assert sum(len(x) == 2 for x in rules) > 2  # several episodes were played


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", SCENARIOS)
def test_action_mask_agrees_with_the_simulator(name: str, backend: str) -> None:
    """A masked move is flagged unsafe by the step and a masked shot invalid (unless the agent was shot
    before it could act); an allowed action never is; an agent that cannot act may only do nothing and
    the simulator ignores whatever it is given."""
    env = GridWarEnv(name, backend=backend)
    scenario = env.scenario
    ids = np.asarray(scenario.action_ids)
    n = scenario.agents_per_team
    rng = np.random.default_rng(3)
    obs, info = env.reset(seed=3)
    counts = {"masked_move": 0, "masked_shot": 0, "only_nothing": 0}
    for _ in range(1500):
        mask = info["action_mask"].reshape(n, -1).astype(bool)
        state = env.sim.state.copy()  # RefSim updates its state in place
        idx = np.empty(n, np.int64)
        for j in range(n):  # choose a masked action half the time, when there is one
            pool = np.flatnonzero(~mask[j]) if rng.random() < 0.5 and (~mask[j]).any() else np.arange(len(ids))
            idx[j] = rng.choice(pool)
        obs, reward, term, trunc, info = env.step(idx if n > 1 else idx[0])
        unsafe = np.atleast_1d(info["unsafe"])
        invalid = np.atleast_1d(info["invalid"])
        shot_first = np.atleast_1d(info["hits_taken"]) > 0
        for j in range(n):
            a, allowed = ids[idx[j]], mask[j, idx[j]]
            if mask[j].sum() == 1:
                counts["only_nothing"] += 1
                assert mask[j, -1] and ids[-1] == NOTHING
                slow_off = scenario.slow_mask[0, j] and state.t[0] % 2 == 1
                assert not state.alive[0, 0, j] or slow_off
                assert not unsafe[j] and not invalid[j]
            elif allowed:
                assert not unsafe[j] and not invalid[j], (a, state.pos[0, 0, j])
            elif a < SHOOT_UP:
                counts["masked_move"] += 1
                assert unsafe[j] or shot_first[j], (a, state.pos[0, 0, j])
            else:
                counts["masked_shot"] += 1
                assert state.ammo[0, 0, j] == 0 and (invalid[j] or shot_first[j])
        if term or trunc:
            obs, info = env.reset()
    assert counts["masked_move"] > 50
    if scenario.advanced:
        assert counts["masked_shot"] > 10
    if name == "nonmarkov":
        assert counts["only_nothing"] > 50  # dead agents and the slow agent on odd steps


def test_mask_names_the_edge_the_mountain_and_the_empty_magazine() -> None:
    # red starts left of the mountain (2,3), on the left edge's neighbour column
    scenario = replace(builtin_scenario("advanced"), red_starts=((1, 3),))
    env = GridWarEnv(scenario, backend="rules")
    _, info = env.reset(seed=0)
    np.testing.assert_array_equal(info["action_mask"], [1, 1, 1, 0, 1, 1, 1, 1, 1])  # right: mountain
    _, info = GridWarEnv("advanced").reset(seed=0)  # on the red base, the bottom-right corner
    np.testing.assert_array_equal(info["action_mask"], [1, 0, 1, 0, 1, 1, 1, 1, 1])
    shoot_down = scenario.action_ids.index(SHOOT_DOWN)
    for _ in range(3):  # empty the magazine (no opponent bullet can reach red within these 4 steps)
        _, _, _, _, info = env.step(shoot_down)
        assert not info["invalid"]
    np.testing.assert_array_equal(info["action_mask"][4:8], [0, 0, 0, 0])
    _, reward, _, _, info = env.step(shoot_down)
    assert info["invalid"] and reward == scenario.rewards.invalid


def test_win_terminates_with_the_terminal_reward() -> None:
    scenario = replace(builtin_scenario("base"), red_starts=((1, 7),))  # one step from the blue base
    env = GridWarEnv(scenario, backend="rules")
    env.reset(seed=0)
    left = scenario.action_ids.index(LEFT)
    obs, reward, term, trunc, info = env.step(left)
    assert term and not trunc and info["winner"] == WINNER_RED
    assert reward == scenario.rewards.valid_action + scenario.rewards.win
    with pytest.raises(RuntimeError, match="reset"):
        env.step(left)


@pytest.mark.parametrize("backend", BACKENDS)
def test_truncated_at_the_step_limit(backend: str) -> None:
    scenario = replace(builtin_scenario("advanced"), max_steps=5)
    env = GridWarEnv(scenario, backend=backend)
    env.reset(seed=0)
    nothing = scenario.action_ids.index(NOTHING)
    for t in range(1, 6):
        _, _, term, trunc, info = env.step(nothing)
        assert info["t"] == t and not term and trunc == (t == 5)
    with pytest.raises(RuntimeError):
        env.step(nothing)
    _, info = env.reset()
    assert info["t"] == 0


# ---- the trace ----

def replay(rows: dict[str, np.ndarray], n_atoms: int) -> tuple[np.ndarray, np.ndarray]:
    """Apply an episode's change rows, in order, to an interpretation of no knowledge."""
    lower, upper = np.zeros(n_atoms), np.ones(n_atoms)
    for a, lo, up in zip(rows["atom"], rows["new_lower"], rows["new_upper"]):
        lower[a], upper[a] = lo, up
    return lower, upper


def test_trace_rows_are_per_episode_and_rebuild_each_episode() -> None:
    scenario = replace(builtin_scenario("advanced"), max_steps=9)
    sink = MemorySink()
    assert isinstance(sink, TraceSink)
    env = GridWarEnv(scenario, backend="rules", trace_sink=sink)
    engine = env.sim.engine
    assert sink.runs == [(engine, scenario)]
    ids = scenario.action_ids
    plan = [UP, UP, NOTHING, SHOOT_UP, LEFT, LEFT, UP, NOTHING, UP]  # spec ids
    returns = []
    for episode in range(3):
        env.reset(seed=10 + episode)
        total, done, k = 0.0, False, 0
        while not done:
            _, r, term, trunc, _ = env.step(ids.index(plan[k % len(plan)]))
            total, done, k = total + r, term or trunc, k + 1
        returns.append((total, k))
        if episode == 1:  # the world as it ends; episode 1 began with a restore, not the engine's t = 0
            rows = sink.rows(1)
            lower, upper = replay(rows, engine.lower.shape[1])
            np.testing.assert_array_equal(lower, engine.lower[0])
            np.testing.assert_array_equal(upper, engine.upper[0])
    env.close()
    assert sink.closed
    assert [b["episode"] for b in sink.begun] == [0, 1, 2]
    assert [b["seed"] for b in sink.begun] == [10, 11, 12]
    for e, (total, steps) in enumerate(returns):
        end = sink.ended[e]
        assert end["episode"] == e and end["steps"] == steps
        assert end["rewards"]["red"] == pytest.approx(total)
        rows = sink.rows(e)
        # episode-local time: every step 0..steps has rows; one engine offset per episode
        assert set(rows["t"].tolist()) == set(range(steps + 1))
        assert len(set(rows["world_episode"].tolist())) == 1  # one simulator episode
        assert (rows["world"] == 0).all()
        # the learner's moves arrive as external facts at the step they were taken
        ext = rows["cause_kind"] == CAUSE_EXTERNAL
        up_on = ext & (rows["atom"] == engine.atom("move", "red-agent-1", "up")) & (rows["new_lower"] == 1.0)
        first_ups = [k + 1 for k in range(steps) if plan[k % len(plan)] == UP and
                     (k == 0 or plan[(k - 1) % len(plan)] != UP)]
        assert sorted(rows["t"][up_on & (rows["t"] > 0)].tolist()) == first_ups
        st = sink.steps(e)
        np.testing.assert_array_equal(st["t"], np.arange(1, steps + 1))
        np.testing.assert_array_equal(st["actions"][:, 0, 0], [plan[k % len(plan)] for k in range(steps)])


def test_a_reset_before_any_step_leaves_the_start_rows_to_the_next_episode() -> None:
    sink = MemorySink()
    env = GridWarEnv("advanced", backend="rules", trace_sink=sink)
    env.reset(seed=0)
    env.reset(seed=1)
    env.step(8)
    engine = env.sim.engine
    env.close()  # the step's rows are handed over at an episode end or at close
    lower, upper = replay(sink.rows(1), engine.lower.shape[1])
    np.testing.assert_array_equal(lower, engine.lower[0])
    np.testing.assert_array_equal(upper, engine.upper[0])
    assert [(e["episode"], e["steps"], e["outcome"]) for e in sink.ended] == [(0, 0, "aborted"), (1, 1, "aborted")]
    assert len(sink.rows(0)["t"]) == 0 and set(sink.rows(1)["t"].tolist()) == {0, 1}


def test_reset_mid_episode_aborts_it_and_reference_backend_streams_steps_only() -> None:
    sink = MemorySink()
    env = GridWarEnv("base", backend="reference", trace_sink=sink)
    env.reset(seed=0)
    env.step(0)
    env.reset(seed=1)
    assert sink.ended[0]["outcome"] == "aborted" and sink.ended[0]["steps"] == 1
    assert sink.rows() == {} and len(sink.steps()["t"]) == 1 and sink.runs[0][0] is None


def test_without_a_sink_the_engine_traces_nothing() -> None:
    env = GridWarEnv("advanced", backend="rules")
    assert not env.sim.engine.trace_on.any()
