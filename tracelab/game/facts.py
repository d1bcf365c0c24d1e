"""A scenario as facts for rules/gridworld/game.rules: the map, the agents, their magazines, the start.

This is data, not behaviour: every dynamic of the game lives in the rule file. Node names follow the
method's trace: cells are their ids (y*W + x), agents `red-agent-1`, bullets `red-bullet-1-2`.
"""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

from tracelab.engine import check_program, load_program
from tracelab.engine.program import Fact, Literal, Program, SourceLoc, Term

from tracelab import RULES_DIR
from tracelab.game.scenario import DIRECTION_DELTAS, TEAMS, Scenario

GAME_RULES = RULES_DIR / "gridworld" / "game.rules"
DIRECTIONS = ("up", "down", "left", "right")  # index = spec direction (action id % 4)


def agent_name(team: int, j: int) -> str:
    return f"{TEAMS[team]}-agent-{j + 1}"


def bullet_name(team: int, j: int, k: int) -> str:
    return f"{TEAMS[team]}-bullet-{j + 1}-{k + 1}"


@lru_cache(maxsize=4)
def game_program(path: str = str(GAME_RULES)) -> Program:
    """The parsed game rules (parsed once per process)."""
    return load_program(path)


def scenario_program(scenario: Scenario, rules: str = str(GAME_RULES)) -> Program:
    """The game rules plus the scenario's facts, as one program."""
    base = game_program(rules)
    program = replace(base, facts=[*base.facts, *scenario_facts(scenario)])
    check_program(program)  # again with the scenario's facts: predicates they set are no longer unknown
    return program


def scenario_facts(scenario: Scenario) -> list[Fact]:
    where = SourceLoc(f"<scenario {scenario.name}>", 0, 0)
    facts: list[Fact] = []

    def fact(pred: str, *args: object, lower: float = 1.0, upper: float = 1.0, static: bool = True) -> None:
        lit = Literal(pred, tuple(Term(str(a), False) for a in args), lower, upper)
        text = f"{lit}{' static' if static else ''}"
        name = f"{pred}({','.join(str(a) for a in args)})"  # each scenario atom is set by one fact
        facts.append(Fact(name=name, literal=lit, static=static, loc=where, text=text))

    w, h = scenario.width, scenario.height
    mountains = set(scenario.mountains)
    cell = scenario.cell_id
    edge_preds = ("edgeUp", "edgeDown", "edgeLeft", "edgeRight")
    for y in range(h):
        for x in range(w):
            c = cell(x, y)
            fact("mountain" if (x, y) in mountains else "free", c)
            for d, (dx, dy) in enumerate(DIRECTION_DELTAS):
                nx, ny = x + dx, y + dy
                if 0 <= nx < w and 0 <= ny < h:
                    fact(f"{DIRECTIONS[d]}Of", cell(nx, ny), c)
                    fact("nextTo", cell(nx, ny), c)
                else:
                    fact(edge_preds[d], c)

    n, ammo = scenario.agents_per_team, scenario.ammo
    slow = scenario.slow_mask
    for t, team in enumerate(TEAMS):
        enemy = 1 - t
        enemy_base = cell(*scenario.bases[enemy])
        for j in range(n):
            a = agent_name(t, j)
            fact("agent", a)
            fact("slow" if slow[t, j] else "fast", a)
            fact("team", a, team)
            fact("enemyBase", a, enemy_base)
            if j == 0:
                fact("teamFirst", a)
            else:
                fact("teamNext", a, agent_name(t, j - 1))
            if j == n - 1:
                fact("teamLast", a, team)
            if ammo == 0:
                fact("unarmed", a)
            for k in range(ammo):
                b = bullet_name(t, j, k)
                fact("bullet", b)
                fact("bulletPos", b, f"p{j * ammo + k + 1}")
                fact("spent", b, lower=0.0, upper=0.0, static=False)
                fact("owner", b, a)
                for e in range(n):
                    fact("target", b, agent_name(enemy, e))
                if k > 0:
                    fact("nextBullet", b, bullet_name(t, j, k - 1))
                if k == ammo - 1:
                    fact("lastBullet", b)
            # the start of the game: non-static facts at t = 0
            sx, sy = scenario.starts(t)[j]
            fact("atLoc", a, cell(sx, sy), static=False)
            fact("alive", a, static=False)
            fact("exposed", a, cell(sx, sy), static=False)
            for event in ("hitNow", "blankHit", "deadOnArrival", "killed"):  # tested for [0,0] by rules
                fact(event, a, lower=0.0, upper=0.0, static=False)
            fact("tally", a, "q0_0")  # no hit yet (game.rules section 2)
            fact("shot", a, lower=0.0, upper=0.0, static=False)
            if ammo:
                fact("ready", bullet_name(t, j, 0), static=False)
    fact("evenStep", "clock", lower=0.0, upper=0.0, static=False)
    fact("countsSteps", "clock")  # game.rules' clock counts the steps (a declared env's spec sets evenStep)
    # phases within a step (game.rules sections 3 and 4) and the tally's counting chains
    fact("clock", "clock")
    fact("acting", "clock", lower=0.0, upper=0.0, static=False)
    fact("walking", "clock", lower=0.0, upper=0.0, static=False)
    # the tally's chain over pairs q<j>_<k>: j enemy bullet places looked at, k hits among them
    kill = scenario.hits_to_kill
    for j in range(n * ammo):
        for k in range(kill):
            fact("keepNext", f"q{j}_{k}", f"q{j + 1}_{k}")
            fact("addNext", f"q{j}_{k}", f"q{j + 1}_{k + 1}")
            fact("addPos", f"q{j + 1}_{k + 1}", f"p{j + 1}")
    for j in range(n * ammo + 1):
        fact("killAt", f"q{j}_{kill}")
    return facts
