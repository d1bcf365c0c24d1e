"""Which Q-networks a GridWar training run has and their shape, from its config and scenario: read by the
trainer (loop.py), the checkpoint's schema (checkpoint.py) and the memory estimate (memory.py), so that
none of them reaches into another for it."""
from __future__ import annotations

from tracelab.game.observe import obs_size
from tracelab.game.scenario import RED, Scenario
from tracelab.train.config import TrainConfig
from tracelab.train.qnet import NetSpec


def network_groups(scenario: Scenario, split: bool) -> dict[str, list[int]]:
    """Network name -> red agents it plays: one shared network, or (split) one for the fast and one for
    the slow agents."""
    n = scenario.agents_per_team
    if not split:
        return {"shared": list(range(n))}
    slow = scenario.slow_mask[RED]
    groups = {"fast": [j for j in range(n) if not slow[j]], "slow": [j for j in range(n) if slow[j]]}
    return {k: v for k, v in groups.items() if v}


def training_net(cfg: TrainConfig, scenario: Scenario) -> NetSpec:
    """The networks' architecture: the observation (stacked in the non-Markov setup), hidden layers, actions."""
    return cfg.network(obs_size(scenario, cfg.non_markov), scenario.n_actions)
