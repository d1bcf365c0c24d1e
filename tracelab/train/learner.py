"""The fused DQN learner, the fast path: the method's network (one tanh hidden layer, as tracelab/train/qnet.py
describes it, laid out flat as tracelab/train/network.py says),
Adam, its replay buffer, and the update, keeping the Learner protocol (learner_protocol.py). To read or change
the update, read tracelab/train/dqn.py: the same update with autograd and torch.optim.Adam, for any network.

The update is written out by hand in torch ops (forward of both networks as batched matmuls, the Smooth L1
gradient, backward through the two layers, Adam on one flat vector) instead of autograd plus
torch.optim: for a 64-unit network the arithmetic is nothing and each torch call's overhead is
everything; this form makes 20 calls where autograd + Adam make several times more
(docs/benchmarks/history.md, "Training"). It computes
what `smooth_l1_loss(Q(s)[a], r + discount * max_a' Q_target(s'))` with autograd and Adam would;
tests/test_learners.py holds it equal to dqn.py's, for every option this learner supports (masked or not).
Double DQN, a dueling head or more hidden layers are dqn.py's alone (`--learner auto` picks it then)."""
from __future__ import annotations

from typing import Any

import numpy as np
import torch

from tracelab.train.learner_protocol import RunningLoss
from tracelab.train.network import block_views, init_row, state_dict_views
from tracelab.train.qnet import NetSpec
from tracelab.train.replay import ReplayBuffer

ADAM_BETAS = (0.9, 0.999)
ADAM_EPS = 1e-8
LOSS_EVERY = 16  # the logged loss is the mean over every 16th update's minibatch
_FUSED_ADAM = getattr(torch, "_fused_adam_", None)  # private, but torch is pinned (torch==2.13.0)


class DQNLearner:
    def __init__(self, spec: NetSpec, *, lr: float, batch: int, buffer: int, generator: torch.Generator,
                 masked: bool = False) -> None:
        if len(spec.hidden) != 1 or spec.dueling:
            raise ValueError(f"the fused learner is written for one tanh hidden layer without a dueling head, "
                             f"not {spec.torch_text()}")
        self.spec = spec
        self.lr = lr
        self.batch = batch
        self.params = torch.empty(2, spec.n_params)   # row 0 online, row 1 target
        self.params[0] = init_row(spec, generator)
        self.params[1] = self.params[0]
        self.grad = torch.zeros(spec.n_params)
        self.adam_m = torch.zeros(spec.n_params)
        self.adam_v = torch.zeros(spec.n_params)
        self.adam_step = 0
        self.updates = 0
        self.buffer = ReplayBuffer(buffer, spec.inputs, spec.actions, batch, masked)
        self.losses = RunningLoss()  # Smooth L1 of the sampled updates since take_loss()
        self._have_q = False
        self._one = torch.ones(())
        self._inv_b = 1.0 / batch
        self._step_t = torch.zeros(())  # Adam's step count as the fused kernel keeps it
        self._bind()

    def _bind(self) -> None:
        """The views and work tensors of the update, made once: parameters are only changed in place, and
        every step of the update writes into a preallocated tensor (`out=`), so it is one torch call per
        line and no allocation. A bias is the last row of its layer's weight block (network.py), so the
        inputs carry a column of ones and one matmul gives a layer's weight and bias gradients."""
        b = self.batch
        d, (h,), a = self.spec.inputs, self.spec.hidden, self.spec.actions
        p = self.params
        self._online = p[0]
        split = (d + 1) * h                                  # where layer 2's block starts
        self._w1a = p[:, :split].view(2, d + 1, h)           # [W1ᵀ; b1] of both networks
        self._w2a = p[:, split:].view(2, h + 1, a)           # [W2ᵀ; b2]
        self._w2t_online = self._w2a[0, :h].t()              # W2 [A, H] of the online network
        self._g1, self._g2 = block_views(self.grad, self.spec)
        buf = self.buffer
        batch = torch.from_numpy(buf.batch)                  # [B, row]: see replay.py's row layout
        hot = 2 * (d + 1)
        self._obs = torch.as_strided(batch, (2, b, d + 1), (d + 1, buf.row, 1))  # s and s', with the ones
        self._s0t = self._obs[0].t()
        self._onehot = batch[:, hot:hot + a]
        self._onehot3 = self._onehot.unsqueeze(2)
        # masked policies: max_a' over the actions the shield allows in s' (penalty 0, else MASKED_Q)
        self._next_penalty = batch[:, buf._pen:buf._pen + a] if buf.masked else None
        self._reward = batch[:, -2:-1]
        self._discount = batch[:, -1:]
        self._pre = torch.empty(2, b, h)
        self._h = torch.ones(2, b, h + 1)                    # tanh outputs, then the column of ones
        self._h_act = self._h[:, :, :h]
        self._h0 = self._h[0, :, :h]
        self._h0t = self._h[0].t()
        self._q = torch.zeros(2, b, a)                       # online(s), target(s')
        self._q0, self._q1 = self._q[0], self._q[1]
        self._q0_3 = self._q0.unsqueeze(1)
        self._q_taken3 = torch.empty(b, 1, 1)
        self._q_taken = self._q_taken3.view(b, 1)
        self._qmax, self._target = torch.empty(b, 1), torch.empty(b, 1)
        self._dq, self._dh, self._dtanh = torch.empty(b, a), torch.empty(b, h), torch.empty(b, h)
        self._denom = torch.empty(self.spec.n_params)

    # ---- learning ----
    def update(self, rng: np.random.Generator) -> None:
        """One gradient step on a minibatch sampled from the buffer with `rng`."""
        self.buffer.sample(rng)
        # no tensor here requires grad: autograd records nothing (no torch.no_grad() needed)
        # both networks' layer 1; tanh(z) = 2 sigmoid(2z) - 1: torch's CPU sigmoid is several times
        # faster than its tanh (docs/benchmarks.md, "Figures behind the code")
        torch.baddbmm(self._pre, self._obs, self._w1a, beta=0.0, alpha=2.0, out=self._pre)
        torch.sigmoid(self._pre, out=self._h_act).mul_(2.0).sub_(1.0)
        torch.bmm(self._h, self._w2a, out=self._q)                           # Q(s), Q_target(s')
        if self._next_penalty is not None:
            self._q1.add_(self._next_penalty)
        torch.amax(self._q1, 1, keepdim=True, out=self._qmax)
        torch.addcmul(self._reward, self._discount, self._qmax, out=self._target)
        if self.updates % LOSS_EVERY == 0:  # the logged loss is sampled: it costs three calls
            torch.bmm(self._q0_3, self._onehot3, out=self._q_taken3)         # Q(s, a) of the taken a
            self.losses.add(torch.nn.functional.smooth_l1_loss(self._q_taken, self._target))
        # d(mean Smooth L1)/dQ(s, a) = clamp(q - y, -1, 1) / B on the taken action, 0 on the others:
        # one-hot * clamp(Q(s) - y) = clamp(one-hot * (Q(s) - y)), without picking Q(s, a) out first;
        # the 1/B goes into the two gradient matmuls (alpha)
        torch.sub(self._q0, self._target, out=self._dq).mul_(self._onehot).clamp_(-1.0, 1.0)
        self._g2.addmm_(self._h0t, self._dq, beta=0.0, alpha=self._inv_b)      # [gW2ᵀ; gb2]
        torch.mm(self._dq, self._w2t_online, out=self._dh)
        torch.addcmul(self._one, self._h0, self._h0, value=-1.0, out=self._dtanh)  # tanh' = 1 - h²
        self._dh.mul_(self._dtanh)
        self._g1.addmm_(self._s0t, self._dh, beta=0.0, alpha=self._inv_b)      # [gW1ᵀ; gb1]
        self._adam()
        self._have_q = True
        self.updates += 1

    def _adam(self) -> None:
        """torch.optim.Adam's update (no weight decay, no amsgrad) on the online row: torch's fused CPU
        Adam kernel, the one `Adam(fused=True)` runs, called directly (two calls, where the optimizer
        object costs many times as much around it: docs/benchmarks.md, "Figures behind the code");
        without it, five calls:
        lr/bc1 · m / (sqrt(v)/sqrt(bc2) + eps) = (lr·sqrt(bc2)/bc1) · m / (sqrt(v) + eps·sqrt(bc2))."""
        b1, b2 = ADAM_BETAS
        self.adam_step += 1
        if _FUSED_ADAM is not None:  # it reads the step count already advanced (as Adam's caller does)
            self._step_t.fill_(self.adam_step)
            _FUSED_ADAM([self._online], [self.grad], [self.adam_m], [self.adam_v], [], [self._step_t],
                        amsgrad=False, lr=self.lr, beta1=b1, beta2=b2, weight_decay=0.0, eps=ADAM_EPS,
                        maximize=False)
            return
        t = self.adam_step
        self.adam_m.lerp_(self.grad, 1.0 - b1)
        self.adam_v.mul_(b2).addcmul_(self.grad, self.grad, value=1.0 - b2)
        bc1, bc2_sqrt = 1.0 - b1 ** t, (1.0 - b2 ** t) ** 0.5
        torch.sqrt(self.adam_v, out=self._denom).add_(ADAM_EPS * bc2_sqrt)
        self._online.addcdiv_(self.adam_m, self._denom, value=-self.lr * bc2_sqrt / bc1)

    def sync_target(self) -> None:
        self.params[1].copy_(self.params[0])

    def online_weights(self) -> dict[str, torch.Tensor]:
        return state_dict_views(self._online, self.spec)

    def take_loss(self) -> float | None:
        """Mean loss of the sampled updates since the last call (None if there were none)."""
        return self.losses.take()

    def q_max_mean(self) -> float | None:
        """Mean over the last minibatch's states of max_a Q(s, a) (online network)."""
        return float(self._q0.amax(1).mean()) if self._have_q else None

    # ---- checkpoints ----
    def state(self) -> dict[str, Any]:
        return {"params": self.params.clone(), "adam_m": self.adam_m.clone(), "adam_v": self.adam_v.clone(),
                "adam_step": self.adam_step, "updates": self.updates, "buffer": self.buffer.state(),
                **self.losses.state(),
                "last_q": self._q.clone() if self._have_q else None}

    def load_state(self, st: dict[str, Any]) -> None:
        if tuple(st["params"].shape) != tuple(self.params.shape):
            raise ValueError(f"checkpoint network has {tuple(st['params'].shape)} parameters, this one "
                             f"{tuple(self.params.shape)}")
        self.params.copy_(st["params"])  # in place: the views stay bound
        self.adam_m.copy_(st["adam_m"])
        self.adam_v.copy_(st["adam_v"])
        self.adam_step, self.updates = int(st["adam_step"]), int(st["updates"])
        self._step_t.fill_(self.adam_step)
        self.buffer.load_state(st["buffer"])
        self.losses.load_state(st)
        self._have_q = st["last_q"] is not None
        if self._have_q:
            self._q.copy_(st["last_q"])
