"""One network for every agent of a team (parameter sharing): each agent's observation is a row of the
batch, followed by its one-hot index among the spec's agents, so that the shared network tells them apart
(the agent indicator of Gupta et al. 2017 and SuperSuit's `agent_indicator_v0`; GridWar's own trainer on
RuleSim put each agent's own blocks first instead: such a policy is refused at load,
env_policy.read_rulesim_spec). What env_trainer.py trains on a world of several agents, and plays in its
evaluations (batched, and traced one world at a time). The encoding is env_source.TeamEncoder."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from tracelab.store.agent_rows import PolicyOutput


class TeamPolicy:
    """A policy over one agent's rows (env_policy.EnvPolicy with a TeamEncoder) acting for every agent of a
    batch of worlds: actions [W, agents] from observations [W, agents, ...] and masks [W, agents, A]."""

    def __init__(self, rows: Any, n_agents: int) -> None:
        self.rows, self.n_agents = rows, n_agents

    def act(self, obs: Any, masks: np.ndarray | None = None) -> np.ndarray:
        return self.decide(obs, masks)[0]

    def decide(self, obs: Any, masks: np.ndarray | None = None) -> tuple[np.ndarray, PolicyOutput]:
        """The greedy actions [W, agents] and their values [W, agents, A] (a traced world records a row per
        agent)."""
        n = self.n_agents
        worlds = len(obs)
        flat = None if masks is None else np.asarray(masks).reshape(worlds * n, -1)
        actions, out = self.rows.decide(obs, flat)
        terms = None if out.term_values is None else out.term_values.reshape(worlds, n, *out.term_values.shape[1:])
        return actions.reshape(worlds, n), replace(out, values=out.values.reshape(worlds, n, -1), term_values=terms)


def team_env_actor(policy: TeamPolicy, env: Any = None) -> Callable[[Any, dict[str, Any]], np.ndarray]:
    """Every agent's greedy action in one world of several agents (play.TeamEnv: observation [agents, ...],
    masks [agents, A]), each agent's decision recorded where `env` records its games."""
    record = env is not None and getattr(env.unwrapped, "records_decisions", False)

    def act(obs: Any, info: dict[str, Any]) -> np.ndarray:
        mask = info.get("action_mask")
        masks = None if mask is None else np.asarray(mask)[None]
        actions, output = policy.decide(np.asarray(obs)[None], masks)
        if record:
            env.unwrapped.decided(output.rows(0), None if masks is None else masks[0])
        return actions[0]
    return act
