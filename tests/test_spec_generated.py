"""Generated parts of a spec (docs/worlds.md, "Generated parts: `for`"): lists, arrays of tables and table
entries repeated over ranges computed from the params; `[env.require]`; and GridWar's war.toml sized by
its params, refused in one located line when a param is wrong or what it would generate is too big."""
from __future__ import annotations

from pathlib import Path

import pytest

from tracelab import RULES_DIR
from tracelab.envs import make_env
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.spec_file import SpecError
from tracelab.expressions import ExpressionError, evaluate

WAR = RULES_DIR / "gridworld" / "war.toml"

# a corridor of `length` cells walked east; each cell pays its number, and the observation reports the
# cell's distance to the goal: the board, rewards, values and start facts all follow `length`
RULES = """\
%mode override
clr:   pushed(A):[0,0] <-1 pushed(A)
snap:  was(C) <-1 at(C)
snapo: was(C):[0,0] <-1 was(C), at(C):[0,0]
go:    at(E) <-! was(C), push(A,east), east(C,E)
left:  at(C):[0,0] <-! was(C), push(A,east), east(C,E)
end:   over(w) <-! at(C), goal(C)
mark:  pushed(A) <-! push(A,east)
"""

SPEC = """\
[env]
rules = ["corridor.rules"]

[env.require]
"length >= 2" = "a corridor has a start and a goal"

[params]
length = 4

[board]
rows = "['S' + '.' * (length - 2) + 'G']"
legend = { G = ["goal"] }
neighbours = { east = [0, 1] }
edge = "none"

[agents]
names = ["robo"]

[actions]
east = ["push(Agent, east)"]
stay = []

[observation]
space = "Box"
[[observation.parts]]
name = "to_goal"
read = "index"
atom = "at(C)"
over = "cells"
values = [{ for = { i = "range(length)" }, each = ["{length - 1 - i}"] }]

[reward.table]
cells = { for = { i = "range(1, length)" }, each = { "at(c0_{i})" = "{i * 10}" } }

[end]
terminated = ["over(w)"]
max_steps = "length * 2"

[start]
facts = ["at(c0_0)", { for = { i = "range(1, length)" }, each = ["at(c0_{i}):[0,0]"] }]
"""


def write(folder: Path, spec: str = SPEC) -> Path:
    (folder / "corridor.rules").write_text(RULES)
    path = folder / "corridor.toml"
    path.write_text(spec)
    return path


@pytest.mark.parametrize("length", [3, 6])
def test_a_world_is_generated_from_its_params(tmp_path: Path, length: int) -> None:
    spec = load_spec(write(tmp_path), length=length)
    assert spec.parts[0].values == tuple(float(length - 1 - i) for i in range(length))  # typed: numbers
    assert [(str(a), v) for a, v in spec.reward_table[0]] == [(f"at(c0_{i})", i * 10.0) for i in range(1, length)]
    assert [str(a) for a in spec.start_facts] == [f"at(c0_{i})" for i in range(length)]
    assert [a.upper for a in spec.start_facts] == [1.0] + [0.0] * (length - 1)
    env = make_env(tmp_path / "corridor.toml", length=length)
    obs, _ = env.reset(seed=0)
    rewards = []
    for _ in range(length - 1):
        obs, r, terminated, truncated, _ = env.step(0)
        rewards.append(r)
    assert rewards == [i * 10.0 for i in range(1, length)] and terminated and obs.tolist() == [0.0]


@pytest.mark.parametrize("old, new, where, fragment", [
    # an atom of a generated entry: located at its template's line, with the variables' values
    ('each = { "at(c0_{i})"', 'each = { "at(c9_{i})"', "corridor.toml:33: reward.table.cells.each.at(c9_{i}) (i = 1)",
     "no constant 'c9_1'"),
    ('each = ["at(c0_{i}):[0,0]"]', 'each = ["at(c0_{i + length}):[0,0]"]',
     "corridor.toml:40: start.facts[1].each[0] (i = 1)", "no constant 'c0_5'"),
    ('"{i * 10}"', '"{i * }"', "corridor.toml:33: reward.table.cells.each.at(c0_{i}) (i = 1)", "not an expression"),
    ('"at(c0_{i})" = "{i * 10}"', '"at(c0_{i // 2})" = 1',
     "corridor.toml:33: reward.table.cells.each.at(c0_{i // 2}) (i = 3)",
     "makes the key 'at(c0_1)' twice"),
    ('i = "range(1, length)"', 'i = "length"', "corridor.toml:33: reward.table.cells.for.i",
     "expected a list of whole numbers or strings, got int"),
    ('i = "range(1, length)"', 'length = "range(3)"', "corridor.toml:33: reward.table.cells.for.length",
     "hides a param"),
    ('"{length - 1 - i}"', '"{length - 1 - i"', "corridor.toml:30: observation.parts[0].values[0].each[0] (i = 0)",
     "a '{' with no '}'"),
    ('cells = { for', 'cells = { fro', "corridor.toml:33: reward.table.cells", "'cells' is not an atom"),
])
def test_generated_parts_mistakes_are_located(tmp_path: Path, old: str, new: str, where: str, fragment: str) -> None:
    assert old in SPEC
    with pytest.raises(SpecError) as e:
        load_spec(write(tmp_path, SPEC.replace(old, new, 1)))
    assert str(e.value).startswith(f"{tmp_path}/{where}") and fragment in str(e.value), str(e.value)


def test_a_requirement_that_fails_names_the_params(tmp_path: Path) -> None:
    with pytest.raises(SpecError, match=r"corridor.toml:5: env.require.length >= 2: a corridor has a start and a "
                                        r"goal \(given length = 1\)"):
        load_spec(write(tmp_path), length=1)


def test_range_is_bounded_before_it_is_built() -> None:
    assert evaluate("range(2, 8, 3)", {}) == [2, 5]
    for text, fragment in (("range(1000000)", "at most 100,000"), ("range(1.5)", "whole numbers"),
                           ("range(1, 2, 0)", "cannot be computed")):
        with pytest.raises(ExpressionError, match=fragment):
            evaluate(text, {})


def test_gridwar_is_sized_by_its_params() -> None:
    spec = load_spec(WAR, agents_per_team=3, ammo=2, health=2.0, advanced=False, reward_scale=0.01)
    assert spec.agents == ("red-agent-1", "red-agent-2", "red-agent-3")
    facts = set(map(str, spec.start_facts))
    assert {"teamNext(red-agent-3,red-agent-2)", "teamLast(blue-agent-3,blue)", "lastBullet(red-bullet-3-2)",
            "bulletPos(blue-bullet-3-2,p6)", "killAt(q6_2)", "addPos(q6_2,p6)"} <= facts
    assert "bullet(red-bullet-1-3)" not in facts and "killAt(q0_1)" not in facts
    assert dict((str(a), v) for a, v in spec.reward_table[0])["won(red)"] == pytest.approx(2.5)
    assert len(spec.parts) == 12 and spec.action_names == ("up", "down", "left", "right", "nothing")
    advanced = load_spec(WAR, advanced=True)
    assert len(advanced.action_names) == 9 and [p.name for p in advanced.parts][4:] == [
        "opponent_bullets", "nearest_bullet_x", "nearest_bullet_y"]


@pytest.mark.parametrize("params, fragment", [
    ({"map": "moon"}, "war.toml:26: env.require.map in maps: a map of [data.maps] (given map = 'moon')"),
    ({"agents_per_team": 0}, "war.toml:24: env.require.agents_per_team >= 1 and ammo >= 0 and health > 0 and "
                             "damage > 0: at least one agent a team"),
    ({"advanced": True, "agents_per_team": 2}, "war.toml:28: env.require.not advanced or agents_per_team == 1: "
                                               "the advanced game plays one agent a team for now"),
    ({"agents_per_team": "five"}, "war.toml:24: env.require.agents_per_team >= 1"),
    ({"agents_per_team": 1000, "ammo": 1000}, "war.toml:15: env.constants[1].for: generates 4,000,000 values"),
])
def test_gridwar_params_that_do_not_make_a_game_are_located(params: dict, fragment: str) -> None:
    with pytest.raises(SpecError) as e:
        load_spec(WAR, **params)
    assert fragment in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_gridwar_generation_is_charged_to_the_memory_budget(monkeypatch: pytest.MonkeyPatch) -> None:
    """Past TRACELAB_SPEC_MEMORY what the params would generate is refused before it is made: at the `for`
    whose values pass it, or at the agents once their atoms are counted."""
    monkeypatch.setenv("TRACELAB_SPEC_MEMORY", "5M")
    with pytest.raises(SpecError, match=r"war.toml:\d+: [a-z.\[\]0-9]+\.for: [\d,]+ generated values brings the spec "
                                        r"to about [\d.]+ MiB once built, over the limit of 5 MiB"):
        load_spec(WAR, agents_per_team=10)
    monkeypatch.setenv("TRACELAB_SPEC_MEMORY", "20M")
    with pytest.raises(SpecError, match=r"war.toml:\d+: [a-z.\[\]0-9]+: .*over the limit of 20 MiB \(set by "
                                        r"TRACELAB_SPEC_MEMORY\)"):
        load_spec(WAR, agents_per_team=10)
    monkeypatch.setenv("TRACELAB_SPEC_MEMORY", "2G")
    assert len(load_spec(WAR, agents_per_team=10).agents) == 10


def test_expressions_of_generated_parts_share_one_step_budget(tmp_path: Path) -> None:
    """100,000 copies of an expression of 100,000 steps would take hours: refused once the copies'
    expressions have spent MAX_GENERATION_STEPS, at the template."""
    spec = SPEC.replace('each = ["{length - 1 - i}"]', 'each = ["{length - 1 - i + len([0] * 99999) * 0}"]')
    spec = spec.replace('for = { i = "range(length)" }, each = ["{length',
                        'for = { i = "range(1000)", k = "range(100)" }, each = ["{length')
    with pytest.raises(SpecError, match=r"corridor.toml:30: observation.parts\[0\].values\[0\].each\[0\] "
                                        r"\(i = \d+, k = \d+\): "
                                        r"generating the spec's parts takes more than 8,000,000 steps"):
        load_spec(write(tmp_path, spec))
