"""Experience replay in preallocated numpy arrays (a ring), sampled into preallocated batch arrays.

A transition is (obs, action, reward, next_obs, discount): `reward` is what was earned from the decision
to the next one (one step for a fast agent, the slow agent's two steps summed with γ), and `discount` the
factor on the bootstrap, γ^k, or 0 when the episode (or the agent) ended."""
from __future__ import annotations

from typing import Any

import numpy as np


class ReplayBuffer:
    def __init__(self, capacity: int, obs_size: int, n_actions: int, batch: int) -> None:
        self.capacity = capacity
        self.n_actions = n_actions
        self.obs = np.zeros((capacity, obs_size), np.float32)
        self.next_obs = np.zeros((capacity, obs_size), np.float32)
        self.action = np.zeros(capacity, np.int64)
        self.reward = np.zeros(capacity, np.float32)
        self.discount = np.zeros(capacity, np.float32)
        self.size = 0
        self.pos = 0
        # the batch the learner reads (torch views of these arrays are made once)
        self.b_obs = np.zeros((2, batch, obs_size), np.float32)  # [obs; next_obs]
        self.b_action = np.zeros((batch, 1), np.int64)
        self.b_onehot = np.zeros((batch, n_actions), np.float32)
        self.b_reward = np.zeros((batch, 1), np.float32)
        self.b_discount = np.zeros((batch, 1), np.float32)
        self._rows = np.arange(batch)

    def add(self, obs: np.ndarray, action: np.ndarray, reward: np.ndarray, next_obs: np.ndarray,
            discount: np.ndarray) -> None:
        """Append K transitions (arrays with a leading axis K), overwriting the oldest when full."""
        k = len(action)
        if k == 0:
            return
        if k > self.capacity:  # only the newest fit
            obs, action, reward, next_obs, discount = (a[-self.capacity:] for a in
                                                       (obs, action, reward, next_obs, discount))
            k = self.capacity
        idx = (self.pos + np.arange(k)) % self.capacity
        self.obs[idx] = obs
        self.next_obs[idx] = next_obs
        self.action[idx] = action
        self.reward[idx] = reward
        self.discount[idx] = discount
        self.pos = (self.pos + k) % self.capacity
        self.size = min(self.size + k, self.capacity)

    def sample(self, rng: np.random.Generator) -> None:
        """Fill the b_* arrays with a uniform sample (with replacement) of stored transitions."""
        idx = rng.integers(0, self.size, len(self._rows))
        np.take(self.obs, idx, axis=0, out=self.b_obs[0])
        np.take(self.next_obs, idx, axis=0, out=self.b_obs[1])
        a = self.action[idx]
        self.b_action[:, 0] = a
        self.b_onehot.fill(0.0)
        self.b_onehot[self._rows, a] = 1.0
        np.take(self.reward, idx, out=self.b_reward[:, 0])
        np.take(self.discount, idx, out=self.b_discount[:, 0])

    # ---- checkpoints ----
    def state(self) -> dict[str, Any]:
        n = self.size
        return {"size": n, "pos": self.pos, "obs": self.obs[:n].copy(), "next_obs": self.next_obs[:n].copy(),
                "action": self.action[:n].copy(), "reward": self.reward[:n].copy(),
                "discount": self.discount[:n].copy()}

    def load_state(self, st: dict[str, Any]) -> None:
        n = int(st["size"])
        if n > self.capacity or st["obs"].shape[1:] != self.obs.shape[1:]:
            raise ValueError(f"checkpoint buffer ({n} x {st['obs'].shape[1:]}) does not fit this buffer "
                             f"({self.capacity} x {self.obs.shape[1:]})")
        for name in ("obs", "next_obs", "action", "reward", "discount"):
            getattr(self, name)[:n] = st[name]
        self.size, self.pos = n, int(st["pos"])
