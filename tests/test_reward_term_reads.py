"""A declared world's reward terms read by its step (fused.read_step on the counting kernel, the same read
in Python on another kernel): each step's quantities are the table atoms' truths and the scaled atom's
bound, summed over an env step's two engine steps (Taxi's fickle passenger), they make the step's reward, and
both kernels read the same."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from test_env_spec import write_world
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.world import DeclaredWorld

TAXI = Path(__file__).resolve().parents[1] / "rules" / "toytext" / "taxi.toml"


def _played(spec, kernel: str, keep: bool, steps: int, seed: int
            ) -> list[tuple[np.ndarray | None, list[float], int]]:
    """Each step's (last_reward_quantities, last_rewards, engine steps) of a world playing seeded random
    actions."""
    world = DeclaredWorld(spec, kernel=kernel)
    world.keep_reward_terms = keep
    rng = np.random.default_rng(seed)
    world.reset(rng)
    out = []
    for _ in range(steps):
        t = world.engine.t
        world.step(int(rng.integers(world.n_actions)), rng)
        q = world.last_reward_quantities
        out.append((None if q is None else q.copy(), list(world.last_rewards), world.engine.t - t))
        if world.terminated() or world.steps >= 40:
            world.reset(rng)
    return out


def test_the_step_reads_a_table_term_and_a_scaled_atoms_bound(tmp_path: Path) -> None:
    spec = load_spec(write_world(tmp_path))  # table: at(c0_3) worth 10; scaled: energy(robo)'s bound, x2
    assert spec.reward_terms == ("at(c0_3)", "energy(Agent)")
    world = DeclaredWorld(spec)
    world.keep_reward_terms = True
    world.reset(np.random.default_rng(0))
    seen = []
    for _ in range(3):  # east three times: the goal at the third
        world.step(1, None)
        seen.append(world.last_reward_quantities.tolist())
        assert world.last_reward_terms.sum(axis=1).tolist() == world.last_rewards
    assert seen == [[[0.0, 0.5]], [[0.0, 0.5]], [[1.0, 0.5]]]
    world.keep_reward_terms = False  # off: the step reads none
    world.step(2, None)
    assert world.last_reward_quantities is None


@pytest.mark.parametrize("params", [{"fickle_passenger": True, "fickle_probability": 1.0}, {}])
def test_both_kernels_read_the_same_terms_and_they_make_the_reward(params: dict) -> None:
    spec = load_spec(TAXI, **params)
    fused = _played(spec, "counting", True, 300, 3)
    lanes = _played(spec, "lanes", True, 300, 3)
    unkept = _played(spec, "counting", False, 300, 3)
    assert [r for _, r, _ in fused] == [r for _, r, _ in lanes] == [r for _, r, _ in unkept]
    values = DeclaredWorld(spec).reward_term_values
    for (qf, rf, _), (ql, _, _) in zip(fused, lanes):
        assert np.array_equal(qf, ql)
        assert np.allclose((qf * values).sum(axis=1), rf)
    counts = np.sum([q for q, _, _ in fused], axis=0)
    assert (counts > 0).sum() >= 2, counts  # the walk paid more than one term (the step's, a bad drop-off)
    # a fickle passenger: some env steps took a second engine step, whose terms were added
    assert any(n == 2 for _, _, n in fused) == bool(params)


def test_a_traced_evaluation_stores_the_same_terms_read_by_the_step_as_read_after_it() -> None:
    from tracelab.bench.terms_ab import compare, step_costs
    r = compare(blocks=1, evaluations=1)  # bench eval's games into three runs: rows compared through `rewards`
    assert r["same_rows"] and r["reward_rows"] > 0 and set(r["thread_ms"]) == {"step", "read", "world"}
    assert set(step_costs(blocks=1, steps=20)["terms_us"]) == {"step", "read"}
