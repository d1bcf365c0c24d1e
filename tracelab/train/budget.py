"""What the documented experiments found about a training's settings, as the one-line notes `tracelab train`
prints: the reward scale that lets the learner learn, and how many training steps DQN needed before it won
anything (the hint a training that ended with no wins well short of that gets)."""
from __future__ import annotations

import math
from typing import NamedTuple


def reward_scale_note(largest_reward: float, scale: float) -> str | None:
    """A note when the learner's largest reward (the game's largest times `scale`) lies outside [1, 10]:
    above, Smooth L1 caps the gradient and Q-values crawl (the method's scale on the war game's hundreds: no
    win in 760,000 steps); below, the default 0.01 on a game whose rewards are already small (the walk of
    tests/test_train.py, rewards up to 10, won nothing in 4,000 steps at 0.01 and 95% at 1). None inside."""
    seen = largest_reward * scale
    if largest_reward <= 0 or 1 <= seen <= 10:
        return None
    better = 10 ** -math.floor(math.log10(largest_reward))     # puts the largest reward in [1, 10)
    if seen > 10:
        return (f"the learner sees rewards up to {seen:g}, where Smooth L1 caps the gradient; --reward-scale "
                f"{better:g} learns several times faster (docs/training.md, \"Reward scale\")")
    return (f"the learner sees rewards up to {seen:g} only (--reward-scale {scale:g} suits rewards in the "
            f"hundreds); --reward-scale {better:g} puts them near 1 (docs/training.md, \"Reward scale\")")


class Budget(NamedTuple):
    learned_from: int   # the fewest steps after which the experiments' runs won
    experiment: int     # the experiment's budget, where every seed had learned (or nearly)
    report: str


# docs/training.md ("Reward scale") and docs/experiments/: 1v1 base learns from 140,000-160,000 steps
# (reward scale 0.01; under 150,000 it depends on the seed), in 200,000; teams (5v5 base, explore-scripted
# 0.5) from ~270,000, in 300,000.
BUDGET_1V1 = Budget(150_000, 200_000, "docs/experiments/1v1-base.md")
BUDGET_TEAMS = Budget(270_000, 300_000, "docs/experiments/5v5-base.md")


def documented_budget(agents_per_team: int) -> Budget:
    return BUDGET_1V1 if agents_per_team == 1 else BUDGET_TEAMS


def too_short_hint(steps: int, wins: int, agents_per_team: int) -> str | None:
    """The hint for a training that won no evaluation game in fewer steps than the experiments needed, or
    None (it won something, or it had the budget and did not learn: not a question of budget)."""
    budget = documented_budget(agents_per_team)
    if wins > 0 or steps >= budget.learned_from:
        return None
    n = agents_per_team
    return (f"0 wins after {steps:,} steps is expected: the documented {n}v{n} runs first won after about "
            f"{budget.learned_from:,} steps ({budget.report}); try --total-timesteps {budget.experiment:.0e}"
            .replace("e+0", "e"))
