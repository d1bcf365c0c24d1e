"""Experience replay in one preallocated numpy array (a ring), sampled into one preallocated batch array.

A transition is (obs, action, reward, next_obs, discount): `reward` is what was earned from the decision
to the next one (one step for a fast agent, the slow agent's two steps summed with γ), and `discount` the
factor on the bootstrap, γ^k, or 0 when the episode (or the agent) ended.

Each transition is one float32 row laid out as the learner reads it: [obs, 1, next_obs, 1, one-hot action,
(next penalty,) reward, discount] (the ones add the biases in the learner's matmuls; the one-hot picks the
taken action's Q-value and carries its gradient). A buffer for a masked policy (`--mask`) also keeps, per
action, a penalty added to the target network's Q(s') before its max: 0 where the action is allowed in s',
MASKED_Q where the shield forbids it, so the bootstrap is the best action the policy could take there. A
buffer for a decomposed network (`train --decompose`) keeps the reward by term: `reward_terms` columns where
the others keep one. So a
minibatch is one `np.take` and the learner's torch tensors are
fixed views of the batch array: sampling costs four numpy calls."""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

MASKED_Q = -1e6  # finite: a terminal transition's discount 0 times it must stay 0 (0 * -inf is nan)


def row_length(obs_size: int, n_actions: int, masked: bool, reward_terms: int = 1) -> int:
    """Floats per transition: [obs, 1, next_obs, 1, one-hot action, (next penalty,) reward(s), discount]."""
    return 2 * (obs_size + 1) + n_actions * (2 if masked else 1) + reward_terms + 1


class Minibatch(NamedTuple):
    """A sampled minibatch by field: numpy views of the buffer's batch array, rewritten by the next sample."""
    obs: np.ndarray           # [B, D]
    actions: np.ndarray       # [B, 1] action indices
    rewards: np.ndarray       # [B, 1], or [B, K] by term (a decomposed network's buffer)
    next_obs: np.ndarray      # [B, D]
    discounts: np.ndarray     # [B, 1]: γ^k, 0 where the episode or the agent ended
    next_penalty: np.ndarray | None  # [B, A] (masked buffers): 0 where allowed in next_obs, MASKED_Q where not


class ReplayBuffer:
    def __init__(self, capacity: int, obs_size: int, n_actions: int, batch: int, masked: bool = False,
                 reward_terms: int = 1) -> None:
        self.capacity = capacity
        self.reward_terms = reward_terms
        self.obs_size = d = obs_size
        self.n_actions = n_actions
        self.masked = masked
        self.row = row_length(d, n_actions, masked, reward_terms)
        self._hot = 2 * (d + 1)  # first column of the one-hot action
        self._pen = self._hot + n_actions  # first column of the next-state penalty (masked buffers)
        self.rows = np.zeros((capacity, self.row), np.float32)
        self.rows[:, d] = 1.0
        self.rows[:, 2 * d + 1] = 1.0
        self.action = np.zeros(capacity, np.int64)  # also kept as ids: checkpoints and tests read them
        self.size = 0
        self.pos = 0
        self.batch = np.zeros((batch, self.row), np.float32)
        # numpy views of the batch by field (the learner makes the same views in torch)
        b = self.batch
        # [obs; next_obs] with the ones (the two halves of a row do not overlap)
        self.b_obs = np.lib.stride_tricks.as_strided(b, (2, batch, d + 1), (4 * (d + 1), 4 * self.row, 4))
        self.b_onehot = b[:, self._hot:self._hot + n_actions]
        self.b_next_penalty = b[:, self._pen:self._pen + n_actions] if masked else None
        self.b_reward = b[:, -1 - reward_terms:-1]
        self.b_discount = b[:, -1:]

    def add(self, obs: np.ndarray, action: np.ndarray, reward: np.ndarray, next_obs: np.ndarray,
            discount: np.ndarray, next_allowed: np.ndarray | None = None) -> None:
        """Append K transitions (arrays with a leading axis K; `reward` [K, terms] by term in a decomposed
        network's buffer), overwriting the oldest when full.
        `next_allowed` [K, A] (masked buffers): the actions the shield allows in next_obs (None: all)."""
        k = len(action)
        if k == 0:
            return
        if k > self.capacity:  # only the newest fit
            obs, action, reward, next_obs, discount = (a[-self.capacity:] for a in
                                                       (obs, action, reward, next_obs, discount))
            next_allowed = None if next_allowed is None else next_allowed[-self.capacity:]
            k = self.capacity
        idx = (self.pos + np.arange(k)) % self.capacity
        d, hot = self.obs_size, self._hot
        rows = self.rows
        rows[idx, :d] = obs
        rows[idx, d + 1:2 * d + 1] = next_obs
        rows[idx, hot:hot + self.n_actions] = 0.0
        rows[idx, hot + np.asarray(action, np.int64)] = 1.0
        if self.masked:
            pen = rows[:, self._pen:self._pen + self.n_actions]
            pen[idx] = 0.0 if next_allowed is None else np.where(np.asarray(next_allowed, bool), 0.0, MASKED_Q)
        rows[idx, -1 - self.reward_terms:-1] = np.asarray(reward).reshape(k, self.reward_terms)
        rows[idx, -1] = discount
        self.action[idx] = action
        self.pos = (self.pos + k) % self.capacity
        self.size = min(self.size + k, self.capacity)

    def sample(self, rng: np.random.Generator) -> None:
        """Fill the batch with a uniform sample (with replacement) of stored transitions."""
        # floor(u * size) for u in [0, 1): uniform over the stored rows, at half the cost of rng.integers
        idx = (rng.random(len(self.batch)) * self.size).astype(np.int64)
        self.rows.take(idx, axis=0, out=self.batch)

    def sample_batch(self, rng: np.random.Generator) -> Minibatch:
        """Sample (as `sample`) and return the minibatch by field."""
        self.sample(rng)
        return Minibatch(self.b_obs[0, :, :-1], self.sampled_actions(), self.b_reward, self.b_obs[1, :, :-1],
                         self.b_discount, self.b_next_penalty)

    def sampled_actions(self) -> np.ndarray:
        """The action ids of the current batch, [B, 1]."""
        return self.b_onehot.argmax(axis=1)[:, None]

    # ---- checkpoints ----
    def state(self) -> dict[str, Any]:
        n, d = self.size, self.obs_size
        st = {"size": n, "pos": self.pos, "obs": self.rows[:n, :d].copy(),
              "next_obs": self.rows[:n, d + 1:2 * d + 1].copy(), "action": self.action[:n].copy(),
              "reward": self.rows[:n, -1 - self.reward_terms:-1].copy(), "discount": self.rows[:n, -1].copy()}
        if self.reward_terms == 1:  # one reward a transition, as checkpoints have always kept it
            st["reward"] = st["reward"][:, 0]
        if self.masked:
            st["next_allowed"] = self.rows[:n, self._pen:self._pen + self.n_actions] == 0.0
        return st

    def load_state(self, st: dict[str, Any]) -> None:
        n = int(st["size"])
        if n > self.capacity or st["obs"].shape[1:] != (self.obs_size,):
            raise ValueError(f"checkpoint buffer ({n} x {st['obs'].shape[1:]}) does not fit this buffer "
                             f"({self.capacity} x {self.obs_size})")
        self.size, self.pos = 0, 0
        self.add(st["obs"], st["action"], st["reward"], st["next_obs"], st["discount"], st.get("next_allowed"))
        self.size, self.pos = n, int(st["pos"])
