"""One DQN learner: online and target network, Adam, its replay buffer, and the update.

The update is written out by hand in torch ops (forward of both networks as batched matmuls, the Smooth L1
gradient, backward through the two layers, Adam on one flat vector) instead of autograd plus
torch.optim: for a 64-unit network the arithmetic is nothing and each torch call's overhead is
everything, and this form needs about a third of the calls (docs/benchmarks.md, "Training"). It computes
what `smooth_l1_loss(Q(s)[a], r + discount * max_a' Q_target(s'))` with autograd and Adam would;
tests/test_train.py checks it against them."""
from __future__ import annotations

from typing import Any

import numpy as np
import torch

from tracelab.train.network import Shape, init_row, q_values, views
from tracelab.train.replay import ReplayBuffer

ADAM_BETAS = (0.9, 0.999)
ADAM_EPS = 1e-8


class DQNLearner:
    def __init__(self, shape: Shape, *, lr: float, batch: int, buffer: int, generator: torch.Generator) -> None:
        self.shape = shape
        self.lr = lr
        self.batch = batch
        self.params = torch.empty(2, shape.n_params)   # row 0 online, row 1 target
        self.params[0] = init_row(shape, generator)
        self.params[1] = self.params[0]
        self.grad = torch.zeros(shape.n_params)
        self.adam_m = torch.zeros(shape.n_params)
        self.adam_v = torch.zeros(shape.n_params)
        self.adam_step = 0
        self.updates = 0
        self.buffer = ReplayBuffer(buffer, shape.inputs, shape.actions, batch)
        self._loss_sum = torch.zeros(())  # Smooth L1 summed over updates since the last take_loss()
        self._loss_n = 0
        self._last_q: torch.Tensor | None = None
        self._one = torch.ones(())
        self._bind()

    def _bind(self) -> None:
        """Views the update and acting use; made once (params are only ever changed in place)."""
        s = self.shape
        o = s.offsets()
        p = self.params
        d, h, a = s.inputs, s.hidden, s.actions
        self._w1s = p[:, o[0]:o[1]].view(2, d, h)
        self._b1s = p[:, o[1]:o[2]].view(2, 1, h)
        self._w2s = p[:, o[2]:o[3]].view(2, h, a)
        self._b2s = p[:, o[3]:o[4]].view(2, 1, a)
        self._gw1, self._gb1, self._gw2, self._gb2 = views(self.grad, s)
        self.online_np = tuple(x.numpy() for x in views(p[0], s))  # shares memory with params
        b = self.buffer
        self._obs = torch.from_numpy(b.b_obs)
        self._action = torch.from_numpy(b.b_action)
        self._onehot = torch.from_numpy(b.b_onehot)
        self._reward = torch.from_numpy(b.b_reward)
        self._discount = torch.from_numpy(b.b_discount)

    # ---- acting ----
    def greedy(self, obs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """argmax_a Q(obs, a) for observations [K, D]; with a mask [K, A] (1 = allowed), among allowed."""
        q = q_values(self.online_np, obs)
        if mask is not None:
            q = np.where(mask.astype(bool), q, -np.inf)
        return q.argmax(axis=1)

    # ---- learning ----
    def update(self, rng: np.random.Generator) -> None:
        """One gradient step on a minibatch sampled from the buffer with `rng`."""
        self.buffer.sample(rng)
        with torch.no_grad():
            s = self._obs                                                  # [2, B, D]: s and s'
            h = torch.baddbmm(self._b1s, s, self._w1s).tanh_()            # [2, B, H]
            q = torch.baddbmm(self._b2s, h, self._w2s)                    # [2, B, A]: online(s), target(s')
            target = torch.addcmul(self._reward, self._discount, q[1].amax(1, keepdim=True))
            q_taken = q[0].gather(1, self._action)                         # [B, 1]
            self._loss_sum += torch.nn.functional.smooth_l1_loss(q_taken, target)
            # d(mean Smooth L1)/dQ(s, a) = clamp(q - y, -1, 1) / B, on the taken action only
            dq = self._onehot * (q_taken - target).clamp_(-1.0, 1.0).div_(self.batch)
            h0 = h[0]
            torch.mm(h0.t(), dq, out=self._gw2)
            torch.sum(dq, 0, out=self._gb2)
            dh = torch.mm(dq, self._w2s[0].t()).mul_(torch.addcmul(self._one, h0, h0, value=-1.0))
            torch.mm(s[0].t(), dh, out=self._gw1)
            torch.sum(dh, 0, out=self._gb1)
            self._adam()
        self._last_q = q
        self._loss_n += 1
        self.updates += 1

    def _adam(self) -> None:
        """torch.optim.Adam's update (no weight decay, no amsgrad) on the online row, in five calls."""
        b1, b2 = ADAM_BETAS
        self.adam_step += 1
        t = self.adam_step
        self.adam_m.lerp_(self.grad, 1.0 - b1)
        self.adam_v.mul_(b2).addcmul_(self.grad, self.grad, value=1.0 - b2)
        bc1, bc2_sqrt = 1.0 - b1 ** t, (1.0 - b2 ** t) ** 0.5
        denom = self.adam_v.sqrt().div_(bc2_sqrt).add_(ADAM_EPS)
        self.params[0].addcdiv_(self.adam_m, denom, value=-self.lr / bc1)

    def sync_target(self) -> None:
        self.params[1].copy_(self.params[0])

    def take_loss(self) -> float | None:
        """Mean loss of the updates since the last call (None if there were none)."""
        if not self._loss_n:
            return None
        value = float(self._loss_sum) / self._loss_n
        self._loss_sum.zero_()
        self._loss_n = 0
        return value

    def q_max_mean(self) -> float | None:
        """Mean over the last minibatch's states of max_a Q(s, a) (online network)."""
        return None if self._last_q is None else float(self._last_q[0].amax(1).mean())

    # ---- checkpoints ----
    def state(self) -> dict[str, Any]:
        return {"params": self.params.clone(), "adam_m": self.adam_m.clone(), "adam_v": self.adam_v.clone(),
                "adam_step": self.adam_step, "updates": self.updates, "buffer": self.buffer.state(),
                "loss_sum": float(self._loss_sum), "loss_n": self._loss_n,
                "last_q": None if self._last_q is None else self._last_q.clone()}

    def load_state(self, st: dict[str, Any]) -> None:
        if tuple(st["params"].shape) != tuple(self.params.shape):
            raise ValueError(f"checkpoint network has {tuple(st['params'].shape)} parameters, this one "
                             f"{tuple(self.params.shape)}")
        self.params.copy_(st["params"])  # in place: the views stay bound
        self.adam_m.copy_(st["adam_m"])
        self.adam_v.copy_(st["adam_v"])
        self.adam_step, self.updates = int(st["adam_step"]), int(st["updates"])
        self.buffer.load_state(st["buffer"])
        self._loss_sum.fill_(st["loss_sum"])
        self._loss_n = int(st["loss_n"])
        self._last_q = st["last_q"]
