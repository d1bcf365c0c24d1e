"""The fused learner's parameter layout: a network described by a NetSpec (tracelab/train/qnet.py) as one flat
row, each linear layer a block [Wᵀ; b] of shape [fan_in + 1, fan_out] (the bias as the weight block's last
row), the layers back to back in the description's order.

The fused learner keeps the online and the target network in one tensor `[2, n]` (row 0 online, row 1 target).
Stacked that way, both networks' forward passes are one batched matmul per layer, the target copy is one
copy, and the optimizer works on one flat vector: the per-operation overhead of torch, not arithmetic, is
what costs here (docs/benchmarks/history.md, "Training"). The row reads back as the description's state dict, so
policies and checkpoints are the same files whichever learner wrote them."""
from __future__ import annotations


import torch

from tracelab.train.qnet import NetSpec, draw_weights


def layer_blocks(spec: NetSpec) -> list[tuple[str, int, int, int]]:
    """(state dict prefix, start in the row, fan in, fan out) of each linear layer; its block is
    row[start : start + (fan_in + 1) * fan_out] viewed as [fan_in + 1, fan_out] = [Wᵀ; b]."""
    out, start = [], 0
    for name, fan_in, fan_out in spec.linears():
        out.append((name, start, fan_in, fan_out))
        start += (fan_in + 1) * fan_out
    return out


def block_views(row: torch.Tensor, spec: NetSpec) -> list[torch.Tensor]:
    """Each layer's [Wᵀ; b] block as a view of `row` (torch), in the description's order."""
    return [row[start:start + (fan_in + 1) * fan_out].view(fan_in + 1, fan_out)
            for _, start, fan_in, fan_out in layer_blocks(spec)]


def state_dict_views(row: torch.Tensor, spec: NetSpec) -> dict[str, torch.Tensor]:
    """A parameter row as the module's state dict (qnet.py's names), of views (live)."""
    out = {}
    for (name, *_), block in zip(layer_blocks(spec), block_views(row, spec)):
        out[f"{name}.weight"], out[f"{name}.bias"] = block[:-1].t(), block[-1]
    return out


def init_row(spec: NetSpec, generator: torch.Generator) -> torch.Tensor:
    """The row of `draw_weights(spec, generator)`: the readable learner's initial network, laid out flat."""
    row = torch.empty(spec.n_params)
    views = state_dict_views(row, spec)
    for name, value in draw_weights(spec, generator).items():
        views[name].copy_(value)
    return row
