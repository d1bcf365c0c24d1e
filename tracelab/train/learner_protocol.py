"""What the Trainer asks of a learner: the whole contract between the loop and an algorithm.

Two learners keep it: the readable one (tracelab/train/dqn.py: an nn.Module, autograd, torch.optim.Adam;
the one to read and change) and the fused one (tracelab/train/learner.py: the same update written out by
hand for the method's one-layer network, several times faster). A new algorithm that learns from the same
replay of transitions is a new class with these methods; the loop does not change (docs/training.md)."""
from __future__ import annotations

from typing import Any, Protocol

import numpy as np
import torch

from tracelab.train.replay import ReplayBuffer


class Learner(Protocol):
    buffer: ReplayBuffer  # the loop stores each closed transition here
    updates: int          # gradient steps made so far

    def update(self, rng: np.random.Generator) -> None:
        """One gradient step on a minibatch sampled from `buffer` with `rng`."""

    def sync_target(self) -> None:
        """Copy the online network into the target network."""

    def take_loss(self) -> float | None:
        """Mean loss of the updates since the last call (None if there were none)."""

    def q_max_mean(self) -> float | None:
        """Mean over the last minibatch's states of max_a Q(s, a) (online network); None before an update."""

    def online_weights(self) -> dict[str, torch.Tensor]:
        """The online network's parameters named as in its module's state dict: live views (acting reads
        them as they change; clone to keep a copy)."""

    def state(self) -> dict[str, Any]:
        """Everything the next update depends on, as tensors and plain values (a checkpoint)."""

    def load_state(self, st: dict[str, Any]) -> None:
        """Continue from `state()`'s output (already checked against the schema the checkpoint implies)."""


class RunningLoss:
    """The mean of the losses added since the last `take()`, summed as a tensor: adding never waits for
    the value (no sync per update)."""

    def __init__(self) -> None:
        self.total, self.count = torch.zeros(()), 0

    def add(self, loss: torch.Tensor) -> None:
        self.total += loss.detach()
        self.count += 1

    def take(self) -> float | None:
        if not self.count:
            return None
        value = float(self.total) / self.count
        self.total.zero_()
        self.count = 0
        return value

    def state(self) -> dict[str, Any]:
        return {"loss_sum": float(self.total), "loss_n": self.count}

    def load_state(self, st: dict[str, Any]) -> None:
        self.total.fill_(st["loss_sum"])
        self.count = int(st["loss_n"])
