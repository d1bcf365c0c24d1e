"""The fused learner's parameter layout for the method's Q-network: one tanh hidden layer, then a linear layer
to one Q-value per action (any other network is the readable learner's, tracelab/train/dqn.py).

The fused learner keeps the online and the target network in one tensor `[2, n]` (row 0 online, row 1 target),
each row holding W1ᵀ [D, H], b1 [H], W2ᵀ [H, A], b2 [A] back to back. Stacked that way, both networks'
forward passes are one batched matmul per layer, the target copy is one copy, and the optimizer works on
one flat vector: the per-operation overhead of torch, not arithmetic, is what costs here
(docs/benchmarks/history.md, "Training"). Saved policies use nn.Sequential(Linear, Tanh, Linear)'s state dict
names, so plain torch loads them too."""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Shape:
    inputs: int   # D: observation length
    hidden: int   # H
    actions: int  # A

    @property
    def n_params(self) -> int:
        d, h, a = self.inputs, self.hidden, self.actions
        return d * h + h + h * a + a

    def offsets(self) -> tuple[int, int, int, int, int]:
        """Start of W1ᵀ, b1, W2ᵀ, b2 in a row, and the row's end."""
        d, h, a = self.inputs, self.hidden, self.actions
        return 0, d * h, d * h + h, d * h + h + h * a, self.n_params


def views(row, shape: Shape) -> tuple:
    """W1ᵀ [D, H], b1 [H], W2ᵀ [H, A], b2 [A] as views of one parameter row (torch or numpy)."""
    o0, o1, o2, o3, o4 = shape.offsets()
    d, h, a = shape.inputs, shape.hidden, shape.actions
    return row[o0:o1].reshape(d, h), row[o1:o2], row[o2:o3].reshape(h, a), row[o3:o4]


def init_row(shape: Shape, generator) -> "torch.Tensor":  # noqa: F821
    """nn.Linear's default initialisation (uniform in ±1/sqrt(fan_in), weights and biases), drawn from a
    seeded torch generator."""
    # deferred: torch, which the fused layout's numpy side does not need
    import torch
    row = torch.empty(shape.n_params)
    w1, b1, w2, b2 = views(row, shape)
    for t, fan_in in ((w1, shape.inputs), (b1, shape.inputs), (w2, shape.hidden), (b2, shape.hidden)):
        bound = 1.0 / math.sqrt(fan_in)
        t.uniform_(-bound, bound, generator=generator)
    return row


def state_dict_views(row, shape: Shape) -> dict:
    """A parameter row as nn.Sequential(Linear(D, H), Tanh(), Linear(H, A))'s state dict, of views (live)."""
    w1, b1, w2, b2 = views(row, shape)
    return {"0.weight": w1.t(), "0.bias": b1, "2.weight": w2.t(), "2.bias": b2}


def to_state_dict(row, shape: Shape) -> dict:
    """The same, copied."""
    return {k: v.contiguous().clone() for k, v in state_dict_views(row, shape).items()}
