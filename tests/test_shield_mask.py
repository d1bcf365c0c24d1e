"""The action mask predicts the shield (docs/envs.md, "Action mask"): GridWar's mask is read from the
shield rules' atoms (`allowed(Agent, Action)`, rules/gridworld/env.rules over game.rules section 7), and
through the spec path a masked move of an agent that may act is stopped and paid as unsafe, an allowed
one never (unless a bullet hits the agent before it acts, which no mask can foresee). The mask's
equality with RefSim's, step by step, is tests/test_gridwar_spec.py's."""
from __future__ import annotations

import numpy as np
import pytest

from tracelab.envs.declared.gridwar import parallel_env

GAMES = {"advanced": ("tracelab/GridWar-advanced-v0", {}), "nonmarkov": ("tracelab/GridWar-nonmarkov-v0", {}),
         "base 3v3": ("tracelab/GridWar-base-v0", {"agents_per_team": 3})}


@pytest.mark.parametrize("game", list(GAMES))
def test_a_masked_move_is_paid_as_unsafe_and_an_allowed_one_never(game: str) -> None:
    env_id, kwargs = GAMES[game]
    env = parallel_env(env_id, max_steps=40, **kwargs)
    spec, world = env.world_spec, env.world
    world.keep_reward_terms = True  # each agent's occurrences of each reward term, every step
    unsafe = spec.reward_terms.index("unsafe(Agent)")
    shot = [k for k, term in enumerate(spec.reward_terms) if term.startswith("shotBy(")]
    moves = [spec.action_names.index(m) for m in ("up", "down", "left", "right")]
    rng = np.random.default_rng(1)
    _, infos = env.reset(seed=1)
    checked = {"masked": 0, "allowed": 0}
    for _ in range(300):
        actions = {a: int(rng.integers(0, len(spec.action_names))) for a in env.agents}
        masks = {a: infos[a]["action_mask"] for a in env.agents}
        _, _, term, trunc, infos = env.step(actions)
        count = world.last_reward_quantities  # [agent, term]
        for j, agent in enumerate(env.possible_agents):
            a, mask = actions[agent], masks[agent]
            if a not in moves or not mask[moves].any() or count[j, shot].any():
                continue  # not a move, an agent that may not act, or hit before it acted
            kind = "allowed" if mask[a] else "masked"
            assert count[j, unsafe] == (kind == "masked"), (agent, spec.action_names[a], mask)
            checked[kind] += 1
        if any(term.values()) or any(trunc.values()):
            _, infos = env.reset()
    assert checked["masked"] > 20 and checked["allowed"] > 20, checked
