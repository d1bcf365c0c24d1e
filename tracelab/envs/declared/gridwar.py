"""GridWar's registered ids (`tracelab/GridWar-{base,advanced,nonmarkov}-v0`) as declared worlds: each id is
a spec in rules/gridworld/ with its fixed params (war.toml sized by its params: agents_per_team, ammo,
health, damage, p_toward, max_steps, map, the rewards and reward_scale, stack_previous; docs/worlds.md,
"GridWar through the same path"). `gym.make(id, **kwargs)` (one agent a team), `gym.make_vec` (one
agent, or a team of several: observations [W, agents, D]), the PettingZoo env (`parallel_env(id,
**kwargs)`) and the commands' `--env id --env-arg ...` all map their keyword arguments onto the spec's
params here (`spec_and_params`), where a keyword the spec cannot honour is refused in one line naming it.
`train --scenario NAME` trains a scenario as the id and params `scenario_env` maps it to."""
from __future__ import annotations

import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym

from tracelab import RULES_DIR
from tracelab.errors import UserError

if TYPE_CHECKING:
    from tracelab.envs.declared.gym_env import DeclaredEnv
    from tracelab.envs.declared.parallel_env import DeclaredParallelEnv
    from tracelab.envs.declared.vector_env import DeclaredVectorEnv
    from tracelab.game.scenario import Scenario

# deferred: the declared envs load the engine (numba) when gym.make calls an entry point here, and the game's
# scenario module only to compare a scenario with what a spec plays; registering the ids does not need them

WAR_SPEC = RULES_DIR / "gridworld" / "war.toml"
# the ids, as the benches, the experiments and the tests name them
BASE_ID, ADVANCED_ID = "tracelab/GridWar-base-v0", "tracelab/GridWar-advanced-v0"
NONMARKOV_ID = "tracelab/GridWar-nonmarkov-v0"
# a GridWar id -> its spec and the params that make its scenario (the others keep the spec's defaults)
GRIDWAR_SPEC_IDS: dict[str, tuple[Path, dict[str, Any]]] = {
    BASE_ID: (WAR_SPEC, {"advanced": False}),
    ADVANCED_ID: (WAR_SPEC, {"advanced": True}),
    # two agents a team, agent 2 slow, observing the last step too: a team (gym.make_vec, parallel_env)
    NONMARKOV_ID: (RULES_DIR / "gridworld" / "war_nonmarkov.toml", {}),
}
# the old RuleSim env's keyword arguments, as the spec's params name them
RENAMED = {"opponent_p": "p_toward"}
# why the spec path cannot honour the others: refused naming them
REFUSED = {
    "trace_sink": "a declared env records its games through trace_writer (a TraceWriter), not a TraceSink",
    "trace_episodes": "a declared env records every game of its trace_writer",
    "trace_agent": "a declared env records its policy's decisions through env.decided()",
}


def spec_and_params(env_id: str, kwargs: dict[str, Any]) -> tuple[Path, dict[str, Any]]:
    """The spec file of a GridWar id and the keyword arguments to load it with: the id's fixed params, then
    `kwargs` with the old RuleSim env's names mapped onto the spec's (opponent_p: p_toward; scenario
    "base" / "advanced": advanced); a UserError names a keyword the spec cannot honour."""
    spec, fixed = GRIDWAR_SPEC_IDS[env_id]
    params = dict(fixed)
    for key, value in kwargs.items():
        if key in REFUSED:
            raise UserError(f"{env_id}: {key}={value!r} is not supported: {REFUSED[key]}")
        if key == "backend" and value != "rules":
            raise UserError(f"{env_id}: backend={value!r} is not supported: the ids play the spec on the rule "
                            "engine (RefSim, the hand-written oracle, is tracelab.game.refsim.RefSim)")
        if key == "scenario":
            if spec != WAR_SPEC or value not in ("base", "advanced"):
                raise UserError(f"{env_id}: scenario={value!r} is not supported: the id names its scenario "
                                "(tracelab/GridWar-base-v0, -advanced-v0, -nonmarkov-v0); its params "
                                "(agents_per_team, map, ...) size it")
            params["advanced"] = value == "advanced"
        elif key != "backend":
            params[RENAMED.get(key, key)] = value
    return spec, params


def make_env(env_id: str, **kwargs: Any) -> DeclaredEnv:
    """gym.make's entry point of a GridWar id: the declared gymnasium Env (one agent a team)."""
    from tracelab.envs.declared.gym_env import DeclaredEnv
    spec, params = spec_and_params(env_id, kwargs)
    _one_agent(env_id, params)
    return DeclaredEnv(spec, **params)


def make_vec_env(env_id: str, num_envs: int = 1, **kwargs: Any) -> DeclaredVectorEnv:
    """gym.make_vec's entry point of a GridWar id: `num_envs` worlds on one engine (SAME_STEP autoreset).
    Several agents a team (agents_per_team > 1, the nonmarkov id): the team vector env, every red agent
    acting in every world (observations [W, agents, D], actions [W, agents]; DeclaredVectorEnv)."""
    from tracelab.envs.declared.vector_env import DeclaredVectorEnv
    spec, params = spec_and_params(env_id, kwargs)
    return DeclaredVectorEnv(spec, num_envs, **params)


def parallel_env(env_id: str = BASE_ID, **kwargs: Any) -> DeclaredParallelEnv:
    """GridWar as a PettingZoo ParallelEnv: every red agent a player (agents_per_team of them), the blue
    team the scripted opponent written as rules."""
    from tracelab.envs.declared.parallel_env import DeclaredParallelEnv
    if env_id not in GRIDWAR_SPEC_IDS:
        raise UserError(f"{env_id!r}: not a GridWar id ({', '.join(GRIDWAR_SPEC_IDS)})")
    spec, params = spec_and_params(env_id, kwargs)
    return DeclaredParallelEnv(spec, **params)


def _one_agent(env_id: str, params: dict[str, Any]) -> None:
    if env_id == NONMARKOV_ID or params.get("agents_per_team", 1) != 1:
        size = params.get("agents_per_team", 2)
        raise UserError(f"{env_id}: agents_per_team={size!r} is not supported by a gymnasium Env, which plays "
                        "one agent (gym.make_vec's team vector env and tracelab.envs.declared.gridwar.parallel_env "
                        "play every red agent)")


def register_gridwar() -> None:
    """Register GridWar's ids (idempotent): gym.make and gym.make_vec build the declared envs."""
    for env_id in GRIDWAR_SPEC_IDS:
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point="tracelab.envs.declared.gridwar:make_env",
                         vector_entry_point="tracelab.envs.declared.gridwar:make_vec_env", kwargs={"env_id": env_id})


def _param_defaults(spec: Path) -> dict[str, Any]:
    """A spec's [params] defaults as its file says them (read as TOML: no rule file is loaded)."""
    return tomllib.loads(spec.read_text())["params"]


def _map_mountains(name: str) -> frozenset[tuple[int, int]]:
    """war.toml's map `name` ([data.maps]) as a scenario's mountains: (x, y), y growing up the rows."""
    rows = tomllib.loads(WAR_SPEC.read_text())["data"]["maps"][name]["rows"]
    return frozenset((x, len(rows) - 1 - r) for r, row in enumerate(rows) for x, ch in enumerate(row) if ch == "M")


def scenario_env(scenario: Scenario, p_toward: float, stack_previous: bool) -> tuple[str, dict[str, Any]]:
    """What the trainer trains for `scenario` (scenario_spec's spec and params): a GridWar id and its
    --env-arg params, params at war.toml's defaults left out (the non-Markov scenario: its id; the advanced
    game with several agents a team: its spec file). UserError naming the scenario and what no spec plays
    (a map other than war.toml's [data.maps], a scenario file's own starts, ...)."""
    where = f"scenario {scenario.name!r}"
    if (scenario.width, scenario.height, scenario.red_base, scenario.blue_base) != (8, 8, (7, 0), (0, 7)) or \
            frozenset(scenario.mountains) not in (_map_mountains("default"), _map_mountains("open")):
        raise UserError(f"{where}: its board is not war.toml's 8x8 map, default or open: write it in war.toml's "
                        f"[data.maps] (as walk4) and train --env rules/gridworld/war.toml --env-arg map=NAME")
    try:
        path, params = scenario_spec(scenario, stack_previous, p_toward)
    except ValueError as e:
        raise UserError(str(e)) from None
    if Path(path) == WAR_NONMARKOV:
        defaults = _param_defaults(WAR_NONMARKOV)
        return NONMARKOV_ID, {k: v for k, v in params.items() if v != defaults[k]}
    if Path(path) != WAR_SPEC:
        return path, params
    name = ADVANCED_ID if params.pop("advanced") else BASE_ID
    defaults = _param_defaults(WAR_SPEC)
    return name, {k: v for k, v in params.items() if v != defaults[k]}


# hand-written specs of scenarios war.toml cannot generate yet, with the fields they fix
WAR_ADVANCED_2V2 = RULES_DIR / "gridworld" / "war_advanced_2v2.toml"
WAR_NONMARKOV = RULES_DIR / "gridworld" / "war_nonmarkov.toml"
_REWARDS = ("win", "loss", "hit_opponent", "got_shot", "valid_action", "unsafe", "invalid")


def scenario_spec(scenario: Any, stack_previous: bool = False,
                  p_toward: float | None = None) -> tuple[str, dict[str, Any]]:
    """The spec file and params that play GridWar's `scenario` (a tracelab.game.scenario.Scenario) as RuleSim
    does; ValueError naming the first field no spec can say (a scenario file's own starts, mountains, board
    size or slow agents beyond the built-in nonmarkov's)."""
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
