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
        # observations carry a last column of ones: the learner's matmuls add the biases with it
        self.obs_size = obs_size
        self.obs = np.ones((capacity, obs_size + 1), np.float32)
        self.next_obs = np.ones((capacity, obs_size + 1), np.float32)
        self.action = np.zeros(capacity, np.int64)
        self.reward = np.zeros(capacity, np.float32)
        self.discount = np.zeros(capacity, np.float32)
        self.size = 0
        self.pos = 0
        # the batch the learner reads (torch views of these arrays are made once)
        self.b_obs = np.ones((2, batch, obs_size + 1), np.float32)  # [obs; next_obs], with the ones
        self.b_action = np.zeros((batch, 1), np.int64)
        self.b_onehot = np.zeros((batch, n_actions), np.float32)  # 1/B on the taken action (the mean's weight)
        self._weight = np.float32(1.0 / batch)
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
        self.obs[idx, :-1] = obs
        self.next_obs[idx, :-1] = next_obs
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
        self.b_onehot[self._rows, a] = self._weight
        np.take(self.reward, idx, out=self.b_reward[:, 0])
        np.take(self.discount, idx, out=self.b_discount[:, 0])

    # ---- checkpoints ----
    def state(self) -> dict[str, Any]:
        n = self.size
        return {"size": n, "pos": self.pos, "obs": self.obs[:n, :-1].copy(), "next_obs": self.next_obs[:n, :-1].copy(),
                "action": self.action[:n].copy(), "reward": self.reward[:n].copy(),
                "discount": self.discount[:n].copy()}

    def load_state(self, st: dict[str, Any]) -> None:
        n = int(st["size"])
        if n > self.capacity or st["obs"].shape[1:] != (self.obs_size,):
            raise ValueError(f"checkpoint buffer ({n} x {st['obs'].shape[1:]}) does not fit this buffer "
                             f"({self.capacity} x {self.obs_size})")
        self.obs[:n, :-1] = st["obs"]
        self.next_obs[:n, :-1] = st["next_obs"]
        for name in ("action", "reward", "discount"):
            getattr(self, name)[:n] = st[name]
        self.size, self.pos = n, int(st["pos"])
