"""From env steps to replay transitions, per red agent, for agents that do not all decide every step.

An agent's transition runs from a step where it decides (alive; a slow agent on even steps) to its next
decision, or to the end of the episode or of its life. The reward in between is summed with γ (one term
for a fast agent, two for the slow agent's two-step move: docs/game.md, "Slow agents (non-Markov
variant)"), and the bootstrap is discounted by γ^k, or cut (0) by termination or death. A truncated episode
(step limit) bootstraps from its last observation: the step limit is not part of the game's state."""
from __future__ import annotations

from typing import Any

import numpy as np


class PendingTransitions:
    """The open transition of every (world, agent): [W, N] arrays, agent observations [W, N, D]."""

    def __init__(self, worlds: int, agents: int, obs_size: int, gamma: float) -> None:
        self.gamma = gamma
        self.obs = np.zeros((worlds, agents, obs_size), np.float32)
        self.action = np.zeros((worlds, agents), np.int64)
        self.reward = np.zeros((worlds, agents))
        self.discount = np.ones((worlds, agents))
        self.open = np.zeros((worlds, agents), bool)

    def start(self, acting: np.ndarray, agent_obs: list[np.ndarray], actions: np.ndarray) -> None:
        """Agents `acting` [W, N] decided `actions` [W, N] on their views `agent_obs[j]` [W, D]."""
        for j, view in enumerate(agent_obs):
            rows = acting[:, j]
            self.obs[rows, j] = view[rows]
        self.action[acting] = actions[acting]
        self.reward[acting] = 0.0
        self.discount[acting] = 1.0
        self.open |= acting

    def earn(self, reward: np.ndarray) -> None:
        """Each open transition earns its agent's step reward [W, N], discounted by the steps it spans."""
        self.reward += np.where(self.open, self.discount * reward, 0.0)
        self.discount = np.where(self.open, self.discount * self.gamma, self.discount)

    def close(self, ends: np.ndarray, cut: np.ndarray) -> dict[str, np.ndarray]:
        """Close the open transitions where `ends` [W, N]; `cut` [W, N] marks those without a bootstrap.
        Returns their world, agent, obs, action, reward and discount (γ^k, 0 where cut)."""
        done = self.open & ends
        w, j = np.nonzero(done)
        out = {"world": w, "agent": j, "obs": self.obs[w, j], "action": self.action[w, j],
               "reward": self.reward[w, j].astype(np.float32),
               "discount": np.where(cut[w, j], 0.0, self.discount[w, j]).astype(np.float32)}
        self.open &= ~done
        return out

    def state(self) -> dict[str, Any]:
        return {k: getattr(self, k).copy() for k in ("obs", "action", "reward", "discount", "open")}

    def load_state(self, st: dict[str, Any]) -> None:
        for k in ("obs", "action", "reward", "discount", "open"):
            getattr(self, k)[...] = st[k]
