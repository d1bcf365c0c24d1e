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
        opts = self.interface_options
        out = []
        for row in probabilities.detach().tolist():
            for name, p in zip(self.class_names, row):
                lower, upper = 0.0, 1.0
                if p > opts.threshold:
                    value = p if opts.snap_value is None else opts.snap_value
                    lower = value if opts.set_lower_bound else 0.0
                    upper = value if opts.set_upper_bound else 1.0
                out.append(Fact(f"{name}({self.identifier}) : [{lower:.3f}, {upper:.3f}]",
                                name=f"{self.identifier}-{name}-fact", start_time=t1, end_time=t2))
        return out
