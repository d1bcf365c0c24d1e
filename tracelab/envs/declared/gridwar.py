"""GridWar declared by one spec, rules/gridworld/war.toml, sized by its params (agents_per_team, ammo,
health, damage, p_toward, max_steps, the rewards and reward_scale, map; docs/worlds.md, "GridWar through
the same path"). The commands that take `--env` (play, train, eval) play GridWar's ids through it, with
`--env-arg` for the params; gymnasium's own `gym.make` of these ids still builds GridWarEnv (RuleSim)
until the envs above the spec are one (issue 38)."""
from __future__ import annotations

from typing import Any

from tracelab import RULES_DIR

WAR_SPEC = RULES_DIR / "gridworld" / "war.toml"
# a GridWar id -> the spec's params that make its scenario (the others keep the spec's defaults)
GRIDWAR_SPEC_IDS: dict[str, dict[str, Any]] = {
    "tracelab/GridWar-base-v0": {"advanced": False},
    "tracelab/GridWar-advanced-v0": {"advanced": True},
}
