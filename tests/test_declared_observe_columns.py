"""The compiled observation reader (observe_kernel.py) reads each atom once: parts that read the same atoms
(GridWar's x and y of an agent are both its cell, `seenAt(A, C)` over the board) share their truth columns,
and the numbers stay each part's own."""
from __future__ import annotations

import numpy as np

from tracelab.envs.declared.gridwar import scenario_spec
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.world import DeclaredWorld
from tracelab.game.scenario import builtin_scenario


def test_parts_reading_the_same_atoms_share_their_columns_and_keep_their_numbers() -> None:
    path, params = scenario_spec(builtin_scenario("base"))
    spec = load_spec(path, **params)
    world = DeclaredWorld(spec)
    program = world.observation_program
    assert len(program.atoms) == len(np.unique(program.atoms))  # x and y read the agent's cells once
    rng = np.random.default_rng(3)
    world.reset(np.random.default_rng(0))
    for _ in range(40):
        numbers = world.observation()
        expected = []
        for k, part in enumerate(spec.parts):  # each part's number, read atom by atom
            held = np.flatnonzero(world.true(world._part_ids[k][0]))
            expected.append(part.value_array[held[0]] if held.size else part.missing)
        assert numbers.tolist() == expected
        world.step(int(rng.integers(world.n_actions)), rng)
        if world.terminated() or world.truncated():
            world.reset(rng)
