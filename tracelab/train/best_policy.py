"""The networks of a run's best evaluation so far. DQN's greedy policy can get worse late in training
(the last, low-ε stretch forgets losing games), so a run keeps the weights of its best evaluation (the
earliest of equals) beside its final ones; the trainer writes them as RUN/policy-best/."""
from __future__ import annotations

from typing import Any

import torch

Weights = dict[str, Any]  # a state dict, or network name -> state dict


def _clone(weights: Weights) -> Weights:
    return {k: v.clone() if isinstance(v, torch.Tensor) else _clone(v) for k, v in weights.items()}


class BestPolicy:
    def __init__(self) -> None:
        self.eval: tuple[float, int] | None = None  # (the evaluation's value, its step)
        self.weights: Weights = {}

    def consider(self, value: float, step: int, weights: Weights) -> bool:
        """Keep a copy of `weights` if `value` beats the best so far; says whether it did."""
        if self.eval is not None and value <= self.eval[0]:
            return False
        self.eval, self.weights = (value, step), _clone(weights)
        return True

    # ---- checkpoints ----
    def state(self) -> dict[str, Any]:
        return {"best_eval": self.eval, "best_weights": self.weights}

    def load_state(self, st: dict[str, Any]) -> None:
        best = st["best_eval"]
        self.eval = None if best is None else (float(best[0]), int(best[1]))
        self.weights = dict(st["best_weights"])
