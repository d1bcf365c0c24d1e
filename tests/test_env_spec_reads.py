"""What the spec format gained for GridWar (issue 26 item 4), in general terms: a board's rays, edges and
several offsets under one neighbour name; an index read as declared numbers with a `missing` one, and a
`count` read; constants only the spec names ([env] constants); a step limit that leaves a terminating
step terminated. Each on the corridor world of test_env_spec.py."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env

from tests.test_env_spec import RULES, SPEC, _located, write_world
from tracelab.envs import make_env
from tracelab.board import Board
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.spec_file import SpecError


def test_rays_edges_and_several_offsets_make_board_facts() -> None:
    board = Board(("...", "..."), "c{row}_{col}", {}, {"near": ((0, 1), (0, -1))}, "none", {}, {}, {},
                  rays={"eastward": (0, 1)}, edges={"northEdge": (-1, 0)})
    facts = board.facts()
    assert [args for p, args in facts if p == "eastward" and args[0] == "c0_0"] == [("c0_0", "c0_1"), ("c0_0", "c0_2")]
    near = sorted(args for p, args in facts if p == "near" and args[0] == "c1_1")
    assert near == [("c1_1", "c1_0"), ("c1_1", "c1_2")]
    assert {args[0] for p, args in facts if p == "northEdge"} == {"c0_0", "c0_1", "c0_2"}
    assert board.fact_count() >= len(facts)


# the corridor's observation as numbers: where the bot is (x from the east end, -1 when nowhere), and how
# many of its two flags are up
NUMBERS = """\
[[observation.parts]]
name = "x"
read = "index"
atom = "at(C)"
over = "cells"
values = [30, 20, 10, 0]
missing = -1
[[observation.parts]]
name = "flags"
read = "count"
atoms = ["bot(robo)", "over(w)"]
"""


def numbers_spec(extra: str = "") -> str:
    head, rest = SPEC.split("[[observation.parts]]", 1)
    return head + NUMBERS + "\n" + rest[rest.index("[reward]"):].replace("[start]", extra + "[start]")


def test_an_index_read_as_numbers_and_a_count(tmp_path: Path) -> None:
    env = make_env(write_world(tmp_path, numbers_spec()))
    assert env.observation_space == spaces.Box(np.array([-1, 0], np.float32), np.array([30, 2], np.float32))
    obs, _ = env.reset(seed=0)
    assert obs.tolist() == [30, 1]
    assert env.step(1)[0].tolist() == [20, 1]
    env.step(1)
    obs, _, terminated, _, _ = env.step(1)
    assert obs.tolist() == [0, 2] and terminated
    check_env(env)


def test_the_nearest_thing_on_the_board(tmp_path: Path) -> None:
    """Two keys lie in the corridor; the part reads the column of the one nearest the bot (a tie goes to
    the key listed first), -1 once the bot is gone."""
    rules = RULES + "lies(k1, c0_3)\nlies(k2, c0_1)\ngone: at(C):[0,0] <-! at(C), push(A,stay)\n"
    nearest = NUMBERS.replace('read = "index"\natom = "at(C)"\nover = "cells"\nvalues = [30, 20, 10, 0]',
                              'read = "nearest"\natom = "lies(Thing, C)"\nthings = ["k1", "k2"]\nfrom = "at(C)"\n'
                              'values = [0, 1, 2, 3]')
    env = make_env(write_world(tmp_path, numbers_spec().replace(NUMBERS, nearest), rules))
    assert env.observation_space.low.tolist() == [-1, 0] and env.observation_space.high.tolist() == [3, 2]
    assert env.reset(seed=0)[0].tolist() == [1, 1]  # k2, one cell away
    assert env.step(1)[0].tolist() == [1, 1]  # on k2
    assert env.step(1)[0].tolist() == [3, 1]  # one cell from each: k1, listed first
    assert env.step(2)[0].tolist() == [-1, 1]  # no bot, no distance


def test_missing_is_read_when_no_atom_holds(tmp_path: Path) -> None:
    rules = RULES + "gone: at(C):[0,0] <-! at(C), push(A,stay)\n"  # staying makes the bot vanish
    env = make_env(write_world(tmp_path, numbers_spec(), rules))
    env.reset(seed=0)
    assert env.step(2)[0].tolist() == [-1, 1]


def test_the_step_limit_leaves_a_terminating_step_terminated(tmp_path: Path) -> None:
    env = make_env(write_world(tmp_path, SPEC.replace("max_steps = 5", "max_steps = 3")))
    env.reset(seed=0)
    flags = [env.step(1)[2:4] for _ in range(3)]
    assert flags == [(False, False), (False, False), (True, False)]  # the goal on the last step: won


def test_constants_only_the_spec_names(tmp_path: Path) -> None:
    spec = SPEC.replace('rules = ["corridor.rules"]', 'rules = ["corridor.rules"]\nconstants = ["robo2"]')
    spec = spec.replace('"bot(robo)"]', '"bot(robo)", "bot(robo2)"]')
    assert [str(a) for a in load_spec(write_world(tmp_path, spec)).start_facts][-1] == "bot(robo2)"


@pytest.mark.parametrize("old, new, key, fragment", [
    ('edge = "none"', 'edge = "none"\nrays = { far = [0, 0] }', "board.rays.far", "a step that moves"),
    ('edge = "none"', 'edge = "none"\nedges = { rim = [1] }', "board.edges.rim", "expected [row step, column step]"),
    ('west = [0, -1]', 'west = [[0, -1], [1]]', "board.neighbours.west", "or a list of them"),
    ('values = [30, 20, 10, 0]', 'values = [30, 20]', "observation.parts[0].values", "a list of 4 finite numbers"),
    ('missing = -1', 'missing = "x"', "observation.parts[0].missing", "unknown name 'x'"),
    ('read = "count"', 'read = "count"\nmissing = 0', "observation.parts[1].missing", "for an index or nearest"),
    ('read = "count"', 'read = "count"\nthings = ["robo"]', "observation.parts[1].things", "read = \"nearest\""),
    ('read = "index"', 'read = "nearest"', "observation.parts[0].things", "missing (required"),
    ('rules = ["corridor.rules"]', 'rules = ["corridor.rules"]\nconstants = ["Robo"]', "env.constants[0]",
     "not a plain constant"),
])
def test_mistakes_in_the_new_keys_are_located(tmp_path: Path, old: str, new: str, key: str, fragment: str) -> None:
    msg = _located(tmp_path, old, new, numbers_spec())
    assert f": {key}: " in msg and fragment in msg, msg


def test_a_discrete_index_takes_no_numbers(tmp_path: Path) -> None:
    text = (numbers_spec().replace('space = "Box"', 'space = "MultiDiscrete"')
            .replace('read = "count"', 'read = "index"'))
    with pytest.raises(SpecError,
                       match=r"observation.parts\[0\].values: `values` is for an index or nearest part of a Box"):
        load_spec(write_world(tmp_path, text))


def test_a_board_of_too_many_facts_is_refused_before_they_are_built(tmp_path: Path) -> None:
    text = numbers_spec().replace('rows = ["S..G"]', 'rows = "[\'.\' * 256] * 256"').replace(
        'edge = "none"', 'edge = "none"\nrays = { n = [-1, 0], s = [1, 0], e = [0, 1], w = [0, -1] }')
    msg = _located(tmp_path, "[board]", "[board]", text)
    assert ": board: makes" in msg and "at most 2,000,000" in msg, msg
