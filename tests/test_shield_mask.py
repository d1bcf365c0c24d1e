"""The action mask of the rules backend is read from the shield rules (game.rules, section 7); the
reference backend computes it from the state. Both must agree, and the rules' mask must be right."""
from __future__ import annotations

import numpy as np
import pytest

from tracelab.envs.common import ActionMasker
from tracelab.game.rulesim import RuleSim
from tracelab.game.scenario import SlowAgents, builtin_scenario, generate_scenario


def scenarios():
    yield builtin_scenario("advanced")
    yield builtin_scenario("nonmarkov")
    yield builtin_scenario("base")
    sc = generate_scenario(6, 5, 3, 0.2, seed=2, advanced=True)
    yield sc.__class__(**{**sc.__dict__, "ammo": 1, "slow_agents": SlowAgents(red=(1,), blue=())})


@pytest.mark.parametrize("scenario", list(scenarios()), ids=lambda s: s.name)
def test_rule_mask_equals_state_mask_and_predicts_the_shield(scenario):
    n_worlds = 6
    sim = RuleSim(scenario, n_worlds, seed=1)
    masker = ActionMasker(scenario)
    ids = np.asarray(scenario.action_ids)
    rng = np.random.default_rng(0)
    checked_unsafe = 0
    for _ in range(120):
        from_rules = masker.for_sim(sim, 0)
        np.testing.assert_array_equal(from_rules, masker(sim.state, 0))
        red = rng.choice(ids, size=(n_worlds, scenario.agents_per_team))
        idx = np.searchsorted(ids, red) if np.all(np.diff(ids) > 0) else \
            np.array([[list(ids).index(a) for a in row] for row in red])
        masked = np.take_along_axis(from_rules, idx[..., None], axis=-1)[..., 0] == 0
        result = sim.step(red, sim.scripted_actions("blue"))
        moves = red <= 3
        # a masked move of an agent that may act is stopped by the shield and flagged unsafe (unless a
        # bullet hits the agent before it acts, which no mask can foresee)
        nothing_allowed = from_rules[..., -1] == 1
        acting = from_rules[..., :4].any(axis=-1)
        stopped = masked & moves & acting & (result.hits_taken[:, 0] == 0)
        checked_unsafe += int(stopped.sum())
        assert nothing_allowed.all()
        assert np.all(result.unsafe[:, 0][stopped])
        done = result.terminated | result.truncated
        if done.any():
            sim.reset(worlds=done)
    assert checked_unsafe > 0 or scenario.name == "base"
