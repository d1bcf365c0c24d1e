"""A spec policy's games in RefSim (tracelab/game/refsim.py, the hand-written oracle): the portability
experiment's other simulator.

No adapter is needed beyond this: RefSim's red observation is the spec's (rules/gridworld/war.toml declares
the same numbers in the same order; tests/test_gridwar_spec.py holds them equal step by step) and the spec's
action i is RefSim's `scenario.action_ids[i]`. Each world is a RefSim of its own, seeded as the spec's vector
env seeds its worlds (world i: seed + i, then that world's own stream over its next games), and the worlds
play their shares of the games as env_policy.play_env_games plays them: with the same seed, the same games
in the same order as the spec's evaluation, if the two simulators agree."""
from __future__ import annotations

import numpy as np

from tracelab.game.refsim import RefSim
from tracelab.game.scenario import RED, Scenario
from tracelab.train.env_policy import EnvEvalResult, EnvPolicy

OUTCOMES = {0: "win", 1: "loss", 2: "terminated"}  # RefSim's winner (red, blue, a draw) as the spec's [end]


def refsim_games(policy: EnvPolicy, scenario: Scenario, games: int, seed: int, worlds: int,
                 opponent_p: float, stack_previous: bool = False) -> EnvEvalResult:
    """`games` greedy games of a one-agent spec policy in RefSim's `scenario` against the scripted opponent
    at `opponent_p`, `worlds` at a time, counted as the spec counts them (env_policy.EnvEvalResult)."""
    if scenario.agents_per_team != 1:
        raise ValueError(f"scenario {scenario.name!r}: RefSim plays one-agent spec policies here "
                         f"({scenario.agents_per_team} agents a team)")
    if policy.mask:
        raise ValueError("a policy that masks its actions: RefSim gives no action mask here")
    w = min(worlds, games)
    quota = np.full(w, games // w, np.int64)
    quota[: games % w] += 1
    sims = [RefSim(scenario, 1, stack_previous=stack_previous) for _ in range(w)]
    for sim in sims:
        sim.opponent_p = opponent_p
    obs = np.stack([sim.reset(seed=seed + i)[0, RED] for i, sim in enumerate(sims)])
    if obs.shape[1] != policy.encoder.size:
        raise ValueError(f"RefSim's {scenario.name!r} observes {obs.shape[1]} numbers, the policy reads "
                         f"{policy.encoder.size}: not the spec of this scenario")
    ids = np.asarray(scenario.action_ids, np.int64)
    ret, length = np.zeros(w), np.zeros(w, np.int64)
    result = EnvEvalResult(wins=0)  # war.toml declares its outcomes
    while quota.any():
        actions = ids[np.asarray(policy.act(obs)).reshape(-1)]
        for k, sim in enumerate(sims):
            res = sim.step(actions[k].reshape(1, 1), sim.scripted_actions("blue"))
            ret[k] += float(res.reward[0, RED])
            length[k] += 1
            obs[k] = res.obs[0, RED]
            terminated, truncated = bool(res.terminated[0]), bool(res.truncated[0])
            if not (terminated or truncated):
                continue
            if quota[k] > 0:
                outcome = OUTCOMES.get(int(res.winner[0]), "truncated") if terminated else "truncated"
                result.add(float(ret[k]), int(length[k]), terminated, truncated and not terminated, outcome)
                quota[k] -= 1
            ret[k], length[k] = 0.0, 0
            obs[k] = sim.reset()[0, RED]
    return result
