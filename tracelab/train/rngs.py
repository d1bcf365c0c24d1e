"""The one owner of a training run's random number generators, all derived from cfg.seed.

Each part is handed its stream here, so a reader finds every source of randomness in one place:
- `numpy`: exploration (the ε draws, the random and the scripted exploring actions) and the learners'
  minibatch sampling. One stream for both, drawn in the loop's order: a seeded run repeats, and
  checkpoints written before the parts existed (one generator state, `rng`) resume exactly.
- `torch`: the networks' initialisation.
- `env_seed()`: the training worlds' reset (their draws, a scripted opponent's among them, come from the
  worlds' generators seeded there; a checkpoint replays the worlds from that reset: env_checkpoint.py).
- `eval_seed(round)`: each evaluation's games, the same for every run of the seed.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import torch


def eval_seed(seed: int, round_no: int) -> int:
    """The seed of evaluation round `round_no` of a run seeded `seed`."""
    return int(np.random.SeedSequence([seed, 1, round_no]).generate_state(1)[0])


class Generators:
    def __init__(self, seed: int) -> None:
        self.seed = seed
        self.numpy = np.random.default_rng(np.random.SeedSequence([seed, 0]))  # exploration and sampling
        self.torch = torch.Generator().manual_seed(seed)                        # network initialisation

    def env_seed(self) -> int:
        return int(np.random.SeedSequence([self.seed, 2]).generate_state(1)[0])

    def eval_seed(self, round_no: int) -> int:
        return eval_seed(self.seed, round_no)

    # ---- checkpoints (the keys checkpoints have always had) ----
    def state(self) -> dict[str, Any]:
        return {"rng": self.numpy.bit_generator.state, "torch_rng": self.torch.get_state()}

    def load_state(self, st: dict[str, Any]) -> None:
        self.numpy.bit_generator.state = st["rng"]
        self.torch.set_state(st["torch_rng"])
