"""How many training steps the documented experiments needed before DQN won anything, and the one-line hint
a training that ended with no wins well short of that gets (`tracelab train` prints it)."""
from __future__ import annotations

from typing import NamedTuple


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
