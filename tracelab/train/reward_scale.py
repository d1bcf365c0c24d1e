"""The reward scale: what the learner sees is the game's rewards (hundreds) times it. Its own module, with
no numpy: `tracelab compare`, a reading command, names a run's scale without loading the trainer's config.

The method uses the rewards as they are (1), which does not learn the 1v1 base scenario in 760,000 steps;
0.01 learns it in 200,000 (docs/training.md, "Reward scale"; docs/experiments/1v1-base.md), so 0.01 is the
default and `--reward-scale 1` the method's."""
from __future__ import annotations

LEARNING_REWARD_SCALE = 0.01
METHOD_REWARD_SCALE = 1.0


def reward_scale_text(scale: float) -> str:
    """How reports name a run's reward scale: `reward scale 0.01 (the method's: 1)`."""
    return (f"reward scale {scale:g}" + (" (the method's)" if scale == METHOD_REWARD_SCALE
                                         else f" (the method's: {METHOD_REWARD_SCALE:g})"))
