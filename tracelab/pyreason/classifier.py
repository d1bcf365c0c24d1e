"""PyReason's classifier integration: a torch model whose [N, C] logits become facts `class(identifier) :
[l, u]`, one per sample and class, that a script adds to the program (`pr.add_fact`). Imported only
when a script uses it (tracelab.pyreason's `LogicIntegratedClassifier`), since it imports torch.

The bounds, as PyReason makes them: softmax over the classes; a class whose probability is above
`threshold` gets [snap, snap] (`snap_value`), or [p, p] without a snap value, where `set_lower_bound` /
`set_upper_bound` False keep that end at 0 / 1; a class at or below the threshold gets [0, 1]."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from .objects import Fact


@dataclass
class ModelInterfaceOptions:
    threshold: float = 0.5
    set_lower_bound: bool = True
    set_upper_bound: bool = True
    snap_value: float | None = 1.0


class LogicIntegratedClassifier(torch.nn.Module):
    """`classifier(x, t1, t2)` -> (logits, probabilities, facts); the facts hold at t1..t2."""

    def __init__(self, model: torch.nn.Module, class_names: Sequence[str], identifier: str = "classifier",
                 interface_options: ModelInterfaceOptions | None = None) -> None:
        super().__init__()
        self.model = model
        self.class_names = list(class_names)
        self.identifier = identifier
        self.interface_options = interface_options or ModelInterfaceOptions()

    def forward(self, x: torch.Tensor, t1: int = 0, t2: int = 0) -> tuple[torch.Tensor, torch.Tensor, list[Fact]]:
        logits = self.model(x)
        if logits.dim() != 2 or logits.size(1) != len(self.class_names):
            raise ValueError(f"LogicIntegratedClassifier: the model gave logits of shape {tuple(logits.shape)}; "
                             f"expected [N, {len(self.class_names)}] (one column per class name)")
        probabilities = torch.softmax(logits, dim=1)
        return logits, probabilities, self._facts(probabilities, t1, t2)

    def _facts(self, probabilities: torch.Tensor, t1: int, t2: int) -> list[Fact]:
        lower, upper = fact_bounds(probabilities, self.interface_options)
        return [class_fact(name, self.identifier, low, up, t1, t2)
                for low_row, up_row in zip(lower.tolist(), upper.tolist())
                for name, low, up in zip(self.class_names, low_row, up_row)]


def fact_bounds(probabilities: torch.Tensor, opts: ModelInterfaceOptions) -> tuple[torch.Tensor, torch.Tensor]:
    """The facts' lower and upper bounds, of the probabilities' shape, computed in their dtype as PyReason
    does (so a probability equal to the threshold in float32 compares as it does there)."""
    like = {"dtype": probabilities.dtype, "device": probabilities.device}
    above = probabilities > torch.tensor(opts.threshold, **like)
    if opts.snap_value is not None:
        snap = torch.tensor(opts.snap_value, **like)
        lower_if = snap if opts.set_lower_bound else torch.tensor(0.0, **like)
        upper_if = snap if opts.set_upper_bound else torch.tensor(1.0, **like)
    else:
        lower_if = probabilities if opts.set_lower_bound else torch.zeros_like(probabilities)
        upper_if = probabilities if opts.set_upper_bound else torch.ones_like(probabilities)
    return (torch.where(above, lower_if, torch.zeros_like(probabilities)),
            torch.where(above, upper_if, torch.ones_like(probabilities)))


def class_fact(label: str, identifier: str, lower: float, upper: float, t1: int, t2: int) -> Fact:
    """PyReason's fact of one class: `label(identifier) : [l, u]` (3 decimals), named
    `identifier-label-fact` (PyReason's parser deletes the spaces of a label such as 'tiger shark')."""
    return Fact(f"{label}({identifier}) : [{lower:.3f}, {upper:.3f}]", name=f"{identifier}-{label}-fact",
                start_time=t1, end_time=t2)
