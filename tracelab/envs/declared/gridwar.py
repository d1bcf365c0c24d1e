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

# hand-written specs of scenarios war.toml cannot generate yet, with the fields they fix
WAR_ADVANCED_2V2 = RULES_DIR / "gridworld" / "war_advanced_2v2.toml"
WAR_NONMARKOV = RULES_DIR / "gridworld" / "war_nonmarkov.toml"
_REWARDS = ("win", "loss", "hit_opponent", "got_shot", "valid_action", "unsafe", "invalid")


def scenario_spec(scenario: Any, stack_previous: bool = False,
                  p_toward: float | None = None) -> tuple[str, dict[str, Any]]:
    """The spec file and params that play GridWar's `scenario` (a tracelab.game.scenario.Scenario) as RuleSim
    does; ValueError naming the first field no spec can say (a scenario file's own starts, mountains, board
    size or slow agents beyond the built-in nonmarkov's)."""
    # deferred: the game's scenario module is only needed to compare a scenario with what a spec plays
    from dataclasses import fields, replace

    from tracelab.game.scenario import builtin_scenario
    p = {} if p_toward is None else {"p_toward": float(p_toward)}
    n = scenario.agents_per_team
    if scenario.is_non_markov or (scenario.advanced and n > 1):
        path, like = (WAR_NONMARKOV, "nonmarkov") if scenario.is_non_markov else (WAR_ADVANCED_2V2, "advanced")
        params: dict[str, Any] = {"max_steps": scenario.max_steps, "stack_previous": stack_previous, **p}
        canonical = replace(builtin_scenario(like), agents_per_team=2, max_steps=scenario.max_steps,
                            red_starts=None, blue_starts=None, rewards=builtin_scenario("base").rewards)
    else:
        default = builtin_scenario("advanced" if scenario.advanced else "base")
        open_map = not scenario.mountains
        path = WAR_SPEC
        params = {"advanced": scenario.advanced, "agents_per_team": n, "ammo": scenario.ammo,
                  "health": scenario.health, "damage": scenario.damage, "max_steps": scenario.max_steps,
                  "map": "open" if open_map else "default", "stack_previous": stack_previous, **p,
                  **{k: getattr(scenario.rewards, k) for k in _REWARDS}}
        canonical = replace(default, agents_per_team=n, ammo=scenario.ammo, health=scenario.health,
                            damage=scenario.damage, max_steps=scenario.max_steps, rewards=scenario.rewards,
                            mountains=() if open_map else default.mountains,
                            **({} if n == 1 else {"red_starts": None, "blue_starts": None}))
    canonical = replace(canonical, name=scenario.name)
    for f in fields(scenario):
        if getattr(scenario, f.name) != getattr(canonical, f.name):
            raise ValueError(f"scenario {scenario.name!r}: its {f.name} ({getattr(scenario, f.name)}) is not one "
                             f"a GridWar spec plays (rules/gridworld/war*.toml: the default or open 8x8 map, "
                             f"every agent on its base, nonmarkov's slow agents, the advanced game at 1 or 2 a "
                             f"team); write a spec for it (docs/worlds.md)")
    return str(path), params
