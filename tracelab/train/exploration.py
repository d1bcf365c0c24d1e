"""ε-greedy's exploring half: the ε schedule and the random actions, drawn from the run's exploration
stream (rngs.Generators.numpy). It keeps no state of its own: ε follows the step, and the stream's
state is saved by its owner."""
from __future__ import annotations

import numpy as np

from tracelab.train.config import TrainConfig


class Exploration:
    def __init__(self, cfg: TrainConfig, rng: np.random.Generator) -> None:
        self.cfg, self.rng = cfg, rng

    def epsilon(self, step: int) -> float:
        """1 during warm-up (the buffer fills with random play), then cfg's schedule."""
        return 1.0 if step < self.cfg.warmup else self.cfg.epsilon(step)

    def draw(self, step: int, shape: tuple[int, ...], n_actions: int,
             masks: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """(which deciders explore, a random action for each) over `shape` (worlds, or worlds x agents):
        uniform over all actions, or (masks [*shape, A]) over the allowed ones."""
        explore = self.rng.random(shape) < self.epsilon(step)
        if masks is None:
            random = self.rng.integers(0, n_actions, shape)
        else:
            random = np.argmax(self.rng.random((*shape, n_actions)) * masks, axis=-1)
        return explore, random

    def mix_in(self, random: np.ndarray, scripted: np.ndarray, masks: np.ndarray | None) -> np.ndarray:
        """--explore-scripted: a share of the exploring actions replaced by `scripted` ones; with masks, a
        forbidden scripted action keeps the random allowed one."""
        take = self.rng.random(random.shape) < self.cfg.explore_scripted
        if masks is not None:
            take &= np.take_along_axis(masks, scripted[..., None], axis=-1)[..., 0].astype(bool)
        return np.where(take, scripted, random)
