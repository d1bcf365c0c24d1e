"""GridWar declared by one spec, rules/gridworld/war.toml, sized by its params (agents_per_team, ammo,
health, damage, p_toward, max_steps, the rewards and reward_scale, map; docs/worlds.md, "GridWar through
the same path"). The commands that take `--env` (play, train, eval) play GridWar's ids through it, with
`--env-arg` for the params, and `train --scenario NAME` trains a scenario as the id and params
`scenario_env` maps it to; gymnasium's own `gym.make` of these ids still builds GridWarEnv (RuleSim)
until the envs above the spec are one (issue 38)."""
from __future__ import annotations

from dataclasses import asdict
from typing import TYPE_CHECKING, Any

from tracelab import RULES_DIR
from tracelab.errors import UserError

if TYPE_CHECKING:
    from tracelab.game.scenario import Scenario

WAR_SPEC = RULES_DIR / "gridworld" / "war.toml"
# a GridWar id -> the spec's params that make its scenario (the others keep the spec's defaults)
GRIDWAR_SPEC_IDS: dict[str, dict[str, Any]] = {
    "tracelab/GridWar-base-v0": {"advanced": False},
    "tracelab/GridWar-advanced-v0": {"advanced": True},
}
# war.toml's [data.maps] as a scenario's mountains (x, y): the built-in scenarios' map, and the same board open
_DEFAULT_MOUNTAINS = ((2, 3), (3, 3), (2, 4), (3, 4), (4, 4), (4, 5))
_MAPS = {frozenset(_DEFAULT_MOUNTAINS): "default", frozenset(): "open"}
_SPEC_DEFAULTS = {"ammo": 3, "health": 1.0, "damage": 1.0, "p_toward": 0.7, "max_steps": 200, "map": "default",
                  "stack_previous": False, "win": 250.0, "loss": -250.0, "hit_opponent": 400.0, "got_shot": -200.0,
                  "valid_action": -2.0, "unsafe": -200.0, "invalid": -10.0}


def scenario_env(scenario: Scenario, p_toward: float, stack_previous: bool) -> tuple[str, dict[str, Any]]:
    """(the GridWar id, its --env-arg params) that play `scenario` against an opponent moving towards red's
    base with `p_toward`, the previous observation after the current one with `stack_previous`; params at
    war.toml's defaults are left out. UserError naming the scenario and what war.toml cannot say of it: a
    map other than its [data.maps], other starts, slow agents, several agents a team (the spec plays them as a
    PettingZoo env, which the trainer does not train yet)."""
    where = f"scenario {scenario.name!r}"
    if scenario.agents_per_team != 1:
        raise UserError(f"{where}: {scenario.agents_per_team} agents a team: training goes through its spec "
                        f"(rules/gridworld/war.toml), whose several agents make a PettingZoo env the trainer does "
                        f"not train yet; train 1v1 (--agents 1), or train an older tracelab for team play")
    if (scenario.width, scenario.height, scenario.red_base, scenario.blue_base) != (8, 8, (7, 0), (0, 7)) or \
            frozenset(scenario.mountains) not in _MAPS:
        raise UserError(f"{where}: its map is not one of war.toml's [data.maps] (default, open): write the map "
                        f"there and train --env rules/gridworld/war.toml --env-arg map=NAME")
    if set(scenario.red_starts or ()) - {scenario.red_base} or set(scenario.blue_starts or ()) - {scenario.blue_base} \
            or scenario.slow_agents.red or scenario.slow_agents.blue:
        raise UserError(f"{where}: starts off the bases and slow agents are not war.toml params")
    params = {"ammo": scenario.ammo, "health": scenario.health, "damage": scenario.damage, "p_toward": p_toward,
              "max_steps": scenario.max_steps, "map": _MAPS[frozenset(scenario.mountains)],
              "stack_previous": stack_previous, **asdict(scenario.rewards)}
    name = "tracelab/GridWar-advanced-v0" if scenario.advanced else "tracelab/GridWar-base-v0"
    return name, {k: v for k, v in params.items() if v != _SPEC_DEFAULTS[k]}
