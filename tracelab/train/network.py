"""The method's Q-network: one tanh hidden layer, then a linear layer to one Q-value per action.

The learner keeps the online and the target network in one tensor `[2, n]` (row 0 online, row 1 target),
each row holding W1ᵀ [D, H], b1 [H], W2ᵀ [H, A], b2 [A] back to back. Stacked that way, both networks'
forward passes are one batched matmul per layer, the target copy is one copy, and the optimizer works on
one flat vector: the per-operation overhead of torch, not arithmetic, is what costs here
(docs/benchmarks.md, "Training"). Saved policies use nn.Sequential(Linear, Tanh, Linear)'s state dict
names, so plain torch loads them too."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STATE_DICT_KEYS = ("0.weight", "0.bias", "2.weight", "2.bias")


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
    import torch
    row = torch.empty(shape.n_params)
    w1, b1, w2, b2 = views(row, shape)
    for t, fan_in in ((w1, shape.inputs), (b1, shape.inputs), (w2, shape.hidden), (b2, shape.hidden)):
        bound = 1.0 / math.sqrt(fan_in)
        t.uniform_(-bound, bound, generator=generator)
    return row


def q_values(params: tuple[np.ndarray, ...], obs: np.ndarray) -> np.ndarray:
    """Q-values [K, A] of observations [K, D] with numpy views (W1ᵀ, b1, W2ᵀ, b2): acting reads the
    learner's live parameters without a copy and without torch's per-call overhead."""
    w1, b1, w2, b2 = params
    return np.tanh(obs @ w1 + b1) @ w2 + b2


def to_state_dict(row, shape: Shape) -> dict:
    """A parameter row as nn.Sequential(Linear(D, H), Tanh(), Linear(H, A))'s state dict (copies)."""
    w1, b1, w2, b2 = views(row, shape)
    return {"0.weight": w1.t().contiguous().clone(), "0.bias": b1.clone(),
            "2.weight": w2.t().contiguous().clone(), "2.bias": b2.clone()}


def from_state_dict(state: dict, shape: Shape) -> "torch.Tensor":  # noqa: F821
    """The parameter row of a state dict written by to_state_dict (or by nn.Sequential)."""
    import torch
    missing = [k for k in STATE_DICT_KEYS if k not in state]
    if missing:
        raise ValueError(f"state dict lacks {missing}; expected the keys {list(STATE_DICT_KEYS)}")
    expect = {"0.weight": (shape.hidden, shape.inputs), "0.bias": (shape.hidden,),
              "2.weight": (shape.actions, shape.hidden), "2.bias": (shape.actions,)}
    for k, want in expect.items():
        if tuple(state[k].shape) != want:
            raise ValueError(f"state dict entry {k} has shape {tuple(state[k].shape)}, expected {want}")
    row = torch.empty(shape.n_params)
    w1, b1, w2, b2 = views(row, shape)
    w1.copy_(state["0.weight"].t())
    b1.copy_(state["0.bias"])
    w2.copy_(state["2.weight"].t())
    b2.copy_(state["2.bias"])
    return row
