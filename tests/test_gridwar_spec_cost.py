"""What GridWar's spec path does per step, counted (issue 38 §4): the work the engine's counters and the
reads' tables show, never a time. tests/test_gridwar_spec.py holds the same spec equal to RefSim."""
from __future__ import annotations

import numpy as np

from tracelab import RULES_DIR
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.world import DeclaredWorld

WAR = RULES_DIR / "gridworld" / "war.toml"


def five_a_team() -> DeclaredWorld:
    return DeclaredWorld(load_spec(WAR, agents_per_team=5), kernel="counting", worlds=1)


def test_a_step_settles_in_one_pass_and_rederives_little() -> None:
    """The mask's rules are immediate rules after the game's: no Δt = 0 rule re-derives in ordinary passes
    (before: 3 passes and ~413 rederivations of ~529 firings a 5v5 step)."""
    world, rng = five_a_team(), np.random.default_rng(0)
    world.reset(rng)
    before = world.engine.stats
    engine_steps = 0  # a reset is an engine step of its own
    for _ in range(60):
        world.step(rng.integers(0, world.n_actions, world.n_agents), rng)
        engine_steps += 1
        if any(world._ends):
            world.reset(rng)
            engine_steps += 1
    after = world.engine.stats
    firings = int((after["firings"] - before["firings"]).sum())
    assert int((after["rederivations"] - before["rederivations"]).sum()) * 10 < firings
    assert int((after["passes"] - before["passes"]).sum()) == engine_steps


def test_a_team_view_is_read_once_and_the_box_reads_no_index_atom() -> None:
    """Every red agent sees the team's view: the observation reads it for the first agent and copies it;
    a Box space with a `missing` for every index part reads no index atom in the fused step."""
    world = five_a_team()
    program = world.observation_program
    assert program.copies == [(agent, 0) for agent in range(1, 5)]
    # the first agent's parts' atoms, each read once (its x and y parts read the same cells: their columns shared)
    assert len(program.atoms) == len({int(a) for ids in world._part_ids for a in np.asarray(ids[0]).ravel()})
    part_ptr, part_atoms = world._reads[:2]
    assert len(part_atoms) == 0 and part_ptr.tolist() == [0]
    world.reset(np.random.default_rng(1))
    first = world.observation(0)
    assert all(np.array_equal(world.observation(a), first) for a in range(1, 5))
