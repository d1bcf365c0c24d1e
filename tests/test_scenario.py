"""Scenario files, their errors, and the map generator."""
from __future__ import annotations

import tomllib
from collections import deque

import numpy as np
import pytest

from tracelab.game.scenario import (
    ADVANCED_ACTION_IDS,
    BASE_ACTION_IDS,
    Rewards,
    Scenario,
    ScenarioError,
    SlowAgents,
    builtin_scenario,
    builtin_scenario_names,
    generate_scenario,
    load_scenario,
    scenario_from_dict,
)

DEFAULT_MOUNTAINS = ((2, 3), (3, 3), (2, 4), (3, 4), (4, 4), (4, 5))

GOOD = """\
name = "x"
width = 8
height = 8
red_base = [7, 0]
blue_base = [0, 7]
mountains = [[2, 3], [3, 3], [2, 4]]
"""


def connected(s: Scenario) -> bool:
    seen = {s.red_base}
    queue = deque([s.red_base])
    mountains = set(s.mountains)
    while queue:
        x, y = queue.popleft()
        for nx, ny in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
            if 0 <= nx < s.width and 0 <= ny < s.height and (nx, ny) not in mountains and (nx, ny) not in seen:
                seen.add((nx, ny))
                queue.append((nx, ny))
    return s.blue_base in seen


# ----- shipped scenarios -----
def test_builtin_scenarios_are_the_spec_defaults():
    assert builtin_scenario_names() == ["advanced", "base", "nonmarkov"]
    base = builtin_scenario("base")
    assert (base.width, base.height, base.red_base, base.blue_base) == (8, 8, (7, 0), (0, 7))
    assert base.mountains == DEFAULT_MOUNTAINS
    assert base.action_ids == (0, 1, 2, 3, 8) and base.n_actions == 5 and not base.advanced
    assert base.red_starts == ((7, 0),) and base.blue_starts == ((0, 7),)
    assert (base.ammo, base.health, base.damage, base.max_steps) == (3, 1.0, 1.0, 200)
    assert base.rewards == Rewards(250, -250, 400, -200, -2, -200, -10)

    adv = builtin_scenario("advanced")
    assert adv.advanced and adv.action_ids == tuple(range(9)) and adv.n_actions == 9
    assert adv.mountains == DEFAULT_MOUNTAINS

    nm = builtin_scenario("nonmarkov")
    assert nm.agents_per_team == 2 and nm.advanced and nm.is_non_markov
    assert nm.slow_agents == SlowAgents(red=(1,), blue=(1,))
    assert nm.slow_mask.tolist() == [[False, True], [False, True]]
    assert not base.is_non_markov


def test_defaults_of_a_minimal_file(tmp_path):
    path = tmp_path / "x.toml"
    path.write_text(GOOD)
    s = load_scenario(path)
    assert s.agents_per_team == 1 and s.red_starts == ((7, 0),) and s.blue_starts == ((0, 7),)
    assert s.action_ids == BASE_ACTION_IDS and s.rewards == Rewards()
    assert s.slow_agents == SlowAgents()
    assert s.mountain_grid[2, 3] and not s.mountain_grid[3, 2]


@pytest.mark.parametrize("name", ["base", "advanced", "nonmarkov"])
def test_to_toml_round_trip_builtin(name):
    s = builtin_scenario(name)
    assert scenario_from_dict(tomllib.loads(s.to_toml())) == s


def test_to_toml_round_trip_everything_set():
    s = Scenario(name='odd "name"', width=9, height=5, red_base=(8, 0), blue_base=(0, 4),
                 mountains=[(4, 2)], agents_per_team=2, red_starts=[(8, 0), (6, 1)],
                 blue_starts=[(0, 4), (1, 3)], ammo=0, health=2.5, damage=0.5, max_steps=17,
                 advanced=True, slow_agents=SlowAgents(red=[0], blue=[]),
                 rewards=Rewards(win=1, loss=-1, hit_opponent=0.5))
    back = scenario_from_dict(tomllib.loads(s.to_toml()))
    assert back == s
    assert back.red_starts == ((8, 0), (6, 1)) and back.slow_agents.red == (0,)


def test_scenarios_are_hashable_and_normalised():
    a = Scenario(name="a", width=4, height=4, red_base=[3, 0], blue_base=[0, 3], mountains=[[1, 1]])
    b = Scenario(name="a", width=4, height=4, red_base=(3, 0), blue_base=(0, 3), mountains=((1, 1),))
    assert a == b and hash(a) == hash(b)
    assert isinstance(a.mountains[0], tuple)


# ----- errors name the file and the field -----
@pytest.mark.parametrize("edit, field, words", [
    ('mountains = [[2, 3], [3, 3], [9, 3]]', "mountains[2]", "(9,3) is outside the 8x8 grid"),
    ('mountains = [[2, 3], [2, 3]]', "mountains[1]", "repeats mountains[0]"),
    ('mountains = [[7, 0]]', "mountains[0]", "is the red base"),
    ('mountains = [[0, 6], [1, 7]]', "mountains", "cut the red base (7,0) off"),
    ('mountains = [[2, "3"]]', "mountains[0]", "expected a cell"),
    ('mountains = "none"', "mountains", "expected a list"),
    ('width = "8"', "width", "expected an integer"),
    ('width = true', "width", "expected an integer"),
    ('width = 0', "width", "at least 1"),
    ('red_base = [0, 7]', "blue_base", "also the red base"),
    ('red_base = [8, 0]', "red_base", "(8,0) is outside the 8x8 grid"),
    ('colour = "red"', "colour", "unknown field"),
    ('agents_per_team = 2\nred_starts = [[7, 0]]', "red_starts", "has 1 cells, agents_per_team is 2"),
    ('blue_starts = [[2, 3]]', "blue_starts[0]", "(2,3) is a mountain"),
    ('blue_starts = [[7, 0]]', "blue_starts[0]", "is the enemy base"),
    ('ammo = -1', "ammo", "at least 0"),
    ('health = 0', "health", "must be positive"),
    ('damage = "lots"', "damage", "expected a number"),
    ('max_steps = 0', "max_steps", "at least 1"),
    ('advanced = 1', "advanced", "expected true or false"),
    ('[rewards]\nwin = 250\nbonus = 3', "rewards.bonus", "unknown field"),
    ('[rewards]\nwin = "big"', "rewards.win", "expected a number"),
    ('rewards = 3', "rewards", "expected a table"),
    ('[slow_agents]\nred = [1]', "slow_agents.red[0]", "agent 1 does not exist"),
    ('[slow_agents]\nred = [0, 0]', "slow_agents.red[1]", "listed twice"),
    ('[slow_agents]\ngreen = [0]', "slow_agents.green", "unknown field"),
])
def test_scenario_file_errors_name_file_and_field(tmp_path, edit, field, words):
    path = tmp_path / "x.toml"
    # Later keys replace earlier ones in our text; TOML forbids duplicates, so drop the replaced line.
    key = edit.split("=")[0].strip()
    lines = [ln for ln in GOOD.splitlines() if ln.split("=")[0].strip() != key]
    path.write_text("\n".join(lines) + "\n" + edit + "\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    err = info.value
    assert str(err).startswith(f"{path}: field '{field}': "), str(err)
    assert words in str(err)
    assert err.field == field and err.source == str(path)


def test_error_message_format_of_the_brief(tmp_path):
    path = tmp_path / "x.toml"
    path.write_text(GOOD.replace("[2, 4]]", "[9, 3]]"))
    with pytest.raises(ScenarioError, match=r"x\.toml: field 'mountains\[2\]': \(9,3\) is outside the 8x8 grid$"):
        load_scenario(path)


def test_missing_required_field(tmp_path):
    path = tmp_path / "x.toml"
    path.write_text(GOOD.replace("height = 8\n", ""))
    with pytest.raises(ScenarioError, match=r"field 'height': is required"):
        load_scenario(path)


def test_invalid_toml_and_missing_file_name_the_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("name = \n")
    with pytest.raises(ScenarioError, match=r"broken\.toml: invalid TOML"):
        load_scenario(path)
    with pytest.raises(ScenarioError, match=r"nope\.toml: cannot read"):
        load_scenario(tmp_path / "nope.toml")


def test_scenario_from_dict_names_its_source():
    d = tomllib.loads(GOOD)
    d["agents_per_team"] = 0
    with pytest.raises(ScenarioError, match=r"^maps/a\.toml: field 'agents_per_team': must be at least 1"):
        scenario_from_dict(d, source="maps/a.toml")


def test_team_sizes_must_fit_the_map():
    d = tomllib.loads(GOOD)
    free = d["width"] * d["height"] - len(d.get("mountains", []))
    d["agents_per_team"] = free // 2
    assert scenario_from_dict(d).agents_per_team == free // 2  # every agent on a cell of its own
    d["agents_per_team"] = free // 2 + 1
    with pytest.raises(ScenarioError, match=rf"^maps/a\.toml: field 'agents_per_team': {free // 2 + 1} agents a "
                                            rf"team do not fit the .* map: it has {free} free cells .* at most "
                                            rf"{free // 2} agents a team"):
        scenario_from_dict(d, source="maps/a.toml")


def test_direct_construction_is_checked_too():
    with pytest.raises(ScenarioError, match=r"<Scenario>: field 'mountains\[0\]': \(5,5\) is outside"):
        Scenario(name="x", width=4, height=4, red_base=(3, 0), blue_base=(0, 3), mountains=[(5, 5)])


def test_unreachable_start_is_an_error():
    # (0,0) is walled in by (1,0) and (0,1); the bases are still connected.
    with pytest.raises(ScenarioError, match=r"field 'red_starts\[0\]': \(0,0\) cannot reach the blue base"):
        Scenario(name="x", width=4, height=4, red_base=(3, 0), blue_base=(0, 3),
                 mountains=[(1, 0), (0, 1)], red_starts=[(0, 0)])


# ----- generator -----
@pytest.mark.parametrize("width, height, n, fraction", [
    (8, 8, 1, 0.1), (16, 12, 5, 0.25), (32, 32, 20, 0.3), (40, 40, 25, 0.45), (6, 3, 2, 0.5),
])
def test_generated_maps_are_connected_and_counted(width, height, n, fraction):
    for seed in range(20):
        s = generate_scenario(width, height, n, fraction, seed, advanced=True)
        assert connected(s)
        assert len(s.mountains) == round(fraction * (width * height - 2))
        assert len(set(s.mountains)) == len(s.mountains)
        assert s.red_base == (width - 1, 0) and s.blue_base == (0, height - 1)
        assert s.red_base not in s.mountains and s.blue_base not in s.mountains
        assert s.agents_per_team == n and len(s.red_starts) == n and len(s.blue_starts) == n
        assert set(s.red_starts) == {s.red_base} and set(s.blue_starts) == {s.blue_base}
        assert s.advanced and s.n_actions == 9


def test_generator_repairs_a_map_that_cut_the_bases_apart():
    # At 60% mountains random placement almost always separates the bases; the repair must keep the count.
    for seed in range(10):
        s = generate_scenario(12, 12, 3, 0.6, seed)
        assert connected(s)
        assert len(s.mountains) == round(0.6 * 142)


def test_generator_is_deterministic_per_seed():
    a = generate_scenario(16, 16, 4, 0.2, seed=7)
    assert a == generate_scenario(16, 16, 4, 0.2, seed=7)
    assert a.mountains != generate_scenario(16, 16, 4, 0.2, seed=8).mountains
    assert scenario_from_dict(tomllib.loads(a.to_toml())) == a


def test_generator_spreads_mountains_uniformly():
    # Over many seeds every non-base cell should be a mountain about `fraction` of the time.
    counts = np.zeros((6, 6))
    for seed in range(400):
        for x, y in generate_scenario(6, 6, 1, 0.25, seed).mountains:
            counts[x, y] += 1
    rate = counts / 400
    rate[5, 0] = rate[0, 5] = 0.25  # the bases
    assert np.all(np.abs(rate - 0.25) < 0.1), rate


def test_generator_rejects_bad_fractions():
    with pytest.raises(ValueError):
        generate_scenario(8, 8, 1, 1.0, 0)
    with pytest.raises(ValueError):
        generate_scenario(8, 8, 1, -0.1, 0)


def test_action_sets():
    assert ADVANCED_ACTION_IDS == tuple(range(9))
    assert BASE_ACTION_IDS == (0, 1, 2, 3, 8)
