"""RefSim, the hand-written oracle, in the situations the spec lists (docs/game.md), plus the scripted policy.

The rules (rules/gridworld/war.toml over game.rules) are held equal to RefSim step by step by
tests/test_gridwar_spec.py. Some tests run also with health 2 (two hits to kill). Maps are 8x8
with red base (7,0) and blue base (0,7) unless a test says otherwise; agents start where the test puts
them. Actions are the spec ids.
"""
from __future__ import annotations

import numpy as np
import pytest

from tracelab.game.observe import obs_size, observe
from tracelab.game.opponent import scripted_actions
from tracelab.game.refsim import RefSim
from tracelab.game.scenario import (
    Scenario,
    SlowAgents,
    builtin_scenario,
    generate_scenario,
)
from tracelab.game.state import (
    WINNER_BLUE,
    WINNER_DRAW,
    WINNER_NONE,
    WINNER_RED,
    StepResult,
)

UP, DOWN, LEFT, RIGHT = 0, 1, 2, 3
S_UP, S_DOWN, S_LEFT, S_RIGHT = 4, 5, 6, 7
NOP = 8
R = Scenario.__dataclass_fields__["rewards"].default_factory()  # the method's reward values


def make(red, blue, *, mountains=(), advanced=True, **kw) -> Scenario:
    return Scenario(name="situation", width=8, height=8, red_base=(7, 0), blue_base=(0, 7),
                    mountains=mountains, agents_per_team=len(red), red_starts=red, blue_starts=blue,
                    advanced=advanced, **kw)


Sim = RefSim
# Rows for tests parametrized over health: health 2 takes two hits to kill
HEALTH_ROWS = [pytest.param(RefSim, 1.0, id="refsim-h1"), pytest.param(RefSim, 2.0, id="refsim-h2")]


@pytest.fixture
def sim_class() -> type:
    return RefSim


@pytest.fixture(scope="module")
def sim_cache() -> dict:
    """Simulators built in this module, by (class, scenario, n_worlds, stack_previous): tests on the same
    scenario share one instance and only reset() it."""
    return {}


@pytest.fixture
def start(sim_class, sim_cache):
    """start(scenario, n_worlds=1, seed=None, stack_previous=False): a just-reset simulator of the class
    under test (reset(seed) re-seeds the scripted policy's rng as a new instance would)."""
    def _start(scenario: Scenario, n_worlds: int = 1, seed: int | None = None,
               stack_previous: bool = False) -> Sim:
        key = (sim_class, scenario, n_worlds, stack_previous)
        if key not in sim_cache:
            sim_cache[key] = sim_class(scenario, n_worlds, stack_previous=stack_previous)
        sim = sim_cache[key]
        sim.reset(seed=seed)
        return sim
    return _start


def step(sim: Sim, red, blue) -> StepResult:
    return sim.step(np.array([red]), np.array([blue]))


def bullets(r: StepResult, team: int, world: int = 0) -> list[tuple[int, int, int]]:
    """Live bullets of `team`: (x, y, direction)."""
    live = r.bullet_live[world] & (r.bullet_owner[:, 0] == team)
    return [(int(x), int(y), int(d)) for (x, y), d in zip(r.bullet_pos[world][live], r.bullet_dir[world][live])]


def pos(r: StepResult, team: int, agent: int = 0, world: int = 0) -> tuple[int, int]:
    return tuple(int(v) for v in r.positions[world, team, agent])


# ----------------------------------------------------------------------------------------------------
# Situations named by the spec
# ----------------------------------------------------------------------------------------------------
def test_agents_crossing_paths_on_one_row(start):
    sim = start(make(red=[(4, 2)], blue=[(2, 2)]))
    r = step(sim, [LEFT], [RIGHT])  # both land on (3,2): agents do not block each other
    assert pos(r, 0) == (3, 2) and pos(r, 1) == (3, 2)
    r = step(sim, [LEFT], [RIGHT])  # and walk on past each other
    assert pos(r, 0) == (2, 2) and pos(r, 1) == (4, 2)
    sim = start(make(red=[(3, 2)], blue=[(2, 2)]))
    r = step(sim, [LEFT], [RIGHT])  # adjacent agents swap cells
    assert pos(r, 0) == (2, 2) and pos(r, 1) == (3, 2)
    assert r.alive.all() and not r.hits_taken.any() and not r.unsafe.any()
    assert r.reward[0].tolist() == [R.valid_action, R.valid_action]
    assert r.winner[0] == WINNER_NONE and not r.done[0]


@pytest.mark.parametrize("blue_action", [NOP, LEFT])
def test_agent_and_enemy_on_one_cell_one_shoots(start, blue_action):
    # Red shoots on its own cell, where blue stands: a point-blank hit, even if blue moves away in the
    # same step (it is hit where it stood before acting).
    sim = start(make(red=[(3, 1)], blue=[(3, 1)]))
    r = step(sim, [S_LEFT], [blue_action])
    assert not r.alive[0, 1, 0] and r.health[0, 1, 0] == 0.0
    assert r.hits_made[0, 0, 0] == 1 and r.hits_taken[0, 1, 0] == 1
    assert bullets(r, 0) == []  # the bullet that hit is gone
    assert r.ammo[0, 0, 0] == 2 and r.alive[0, 0, 0]
    if blue_action == LEFT:
        assert pos(r, 1) == (2, 1)  # its move happened at the same moment as the shot
    assert r.winner[0] == WINNER_RED and r.terminated[0]
    assert r.reward[0, 0] == R.valid_action + R.hit_opponent + R.win
    assert r.reward[0, 1] == R.valid_action + R.got_shot + R.loss


def test_bullet_speed_along_a_row(start):
    sim = start(make(red=[(1, 1)], blue=[(0, 7)]))
    r = step(sim, [S_RIGHT], [NOP])
    assert bullets(r, 0) == [(1, 1, 3)]  # created on the shooter's cell, not moved yet
    for x in range(2, 8):
        r = step(sim, [NOP], [NOP])
        assert bullets(r, 0) == [(x, 1, 3)]  # one cell per step
    r = step(sim, [NOP], [NOP])
    assert bullets(r, 0) == []
    assert r.t[0] == 8


def test_bullet_into_mountain(start):
    sim = start(make(red=[(1, 1)], blue=[(5, 1)], mountains=[(4, 1)]))
    step(sim, [S_RIGHT], [NOP])
    r = step(sim, [NOP], [NOP])
    assert bullets(r, 0) == [(2, 1, 3)]
    r = step(sim, [NOP], [NOP])
    assert bullets(r, 0) == [(3, 1, 3)]
    r = step(sim, [NOP], [NOP])  # enters (4,1), a mountain: removed; blue behind it is safe
    assert bullets(r, 0) == []
    for _ in range(3):
        r = step(sim, [NOP], [NOP])
    assert r.alive.all() and r.hits_taken.sum() == 0


@pytest.mark.parametrize("shooter, action", [((3, 7), S_UP), ((3, 0), S_DOWN), ((0, 3), S_LEFT),
                                             ((7, 3), S_RIGHT)])
def test_bullet_leaves_map_each_direction(start, shooter, action):
    sim = start(make(red=[shooter], blue=[(0, 7)]))
    r = step(sim, [action], [NOP])
    assert bullets(r, 0) == [(shooter[0], shooter[1], action - 4)]
    r = step(sim, [NOP], [NOP])
    assert bullets(r, 0) == [] and (r.bullet_pos[0] == -1).all()
    assert r.alive.all()


@pytest.mark.parametrize("blue_x", [5, 4])  # even gap: they share a cell; odd gap: they swap cells
def test_two_bullets_pass_through_each_other(start, blue_x):
    sim = start(make(red=[(1, 2)], blue=[(blue_x, 2)]))
    step(sim, [S_RIGHT], [S_LEFT])
    for k in range(1, blue_x - 1):
        r = step(sim, [NOP], [NOP])
        assert bullets(r, 0) == [(1 + k, 2, 3)]
        assert bullets(r, 1) == [(blue_x - k, 2, 2)]
    assert r.alive.all() and r.hits_taken.sum() == 0


def test_bullets_pass_a_teammate(start):
    sim = start(make(red=[(1, 2), (3, 2)], blue=[(6, 2), (0, 7)]))
    step(sim, [S_RIGHT, NOP], [NOP, NOP])
    step(sim, [NOP, NOP], [NOP, NOP])
    r = step(sim, [NOP, NOP], [NOP, NOP])  # on the teammate's cell: no friendly fire
    assert bullets(r, 0) == [(3, 2, 3)]
    assert r.alive[0, 0].all() and r.hits_taken[0, 0].sum() == 0 and r.health[0, 0, 1] == 1.0
    step(sim, [NOP, NOP], [NOP, NOP])
    step(sim, [NOP, NOP], [NOP, NOP])
    r = step(sim, [NOP, NOP], [NOP, NOP])  # and goes on to hit the enemy beyond
    assert not r.alive[0, 1, 0] and r.hits_made[0, 0, 0] == 1


@pytest.mark.parametrize("fresh", [False, True])
def test_agent_walks_into_bullet(start, fresh):
    sim = start(make(red=[(2, 1)], blue=[(3, 2) if not fresh else (3, 1)]))
    if not fresh:
        step(sim, [S_UP], [NOP])     # bullet at (2,1)
        r = step(sim, [NOP], [LEFT])  # bullet moves to (2,2), then blue walks into it
    else:
        r = step(sim, [S_UP], [LEFT])  # blue walks onto the shooter's cell as the bullet appears there
    assert pos(r, 1) == (2, 2) if not fresh else (2, 1)
    assert not r.alive[0, 1, 0] and r.hits_taken[0, 1, 0] == 1 and r.hits_made[0, 0, 0] == 1
    assert bullets(r, 0) == []
    assert r.winner[0] == WINNER_RED
    assert r.reward[0, 1] == R.valid_action + R.got_shot + R.loss


@pytest.mark.parametrize("sim_class, health", HEALTH_ROWS)
def test_agent_and_bullet_swap_cells(start, health):
    sim = start(make(red=[(1, 1)], blue=[(2, 1)], health=health))
    step(sim, [S_RIGHT], [NOP])  # bullet on (1,1), blue on (2,1)
    r = step(sim, [NOP], [LEFT])  # bullet -> (2,1), blue -> (1,1): no tunnelling
    assert r.hits_taken[0, 1, 0] == 1 and r.hits_made[0, 0, 0] == 1
    assert bullets(r, 0) == []
    if health == 1.0:
        assert not r.alive[0, 1, 0] and pos(r, 1) == (2, 1)  # killed before it could move
    else:
        assert r.alive[0, 1, 0] and r.health[0, 1, 0] == 1.0 and pos(r, 1) == (1, 1)  # hit once only


def test_mutual_kills_draw(start):
    sim = start(make(red=[(1, 2)], blue=[(5, 2)]))
    step(sim, [S_RIGHT], [S_LEFT])
    for _ in range(3):
        r = step(sim, [NOP], [NOP])
        assert r.alive.all()
    r = step(sim, [NOP], [NOP])  # both bullets arrive in the same step
    assert not r.alive.any()
    assert r.winner[0] == WINNER_DRAW and r.terminated[0] and not r.truncated[0]
    # Killed before acting: no action cost; a draw adds nothing.
    assert r.reward[0].tolist() == [R.hit_opponent + R.got_shot] * 2


def test_point_blank_mutual_shots(start):
    sim = start(make(red=[(3, 1)], blue=[(3, 1)]))
    r = step(sim, [S_UP], [S_RIGHT])
    assert not r.alive.any()
    assert r.hits_made[0, :, 0].tolist() == [1, 1] and r.hits_taken[0, :, 0].tolist() == [1, 1]
    assert bullets(r, 0) == [] and bullets(r, 1) == []
    assert r.winner[0] == WINNER_DRAW
    assert r.reward[0].tolist() == [R.valid_action + R.hit_opponent + R.got_shot] * 2


@pytest.mark.parametrize("sim_class, health", HEALTH_ROWS)
def test_point_blank_hit_comes_before_a_walk_in(start, health):
    # Blue leaves red 0's cell as red 0 shoots point blank, and walks onto (2,1), where red 1's bullet
    # has just arrived. Point-blank damage lands first: killed, blue is not hit again by the walk-in
    # (the bullet stays); with health left, the walk-in hits it too.
    sim = start(make(red=[(3, 1), (1, 1)], blue=[(3, 1), (0, 7)], health=health))
    step(sim, [NOP, S_RIGHT], [NOP, NOP])  # red 1's bullet on (1,1)
    r = step(sim, [S_UP, NOP], [LEFT, NOP])  # bullet -> (2,1); point blank on (3,1); blue -> (2,1)
    assert pos(r, 1) == (2, 1) and not r.alive[0, 1, 0]
    assert r.hits_made[0, 0].tolist() == ([1, 0] if health == 1.0 else [1, 1])
    assert r.hits_taken[0, 1, 0] == (1 if health == 1.0 else 2)
    assert bullets(r, 0) == ([(2, 1, 3)] if health == 1.0 else [])


def test_shooting_until_ammo_runs_out_then_invalid_shot(start):
    sim = start(make(red=[(4, 1)], blue=[(0, 7)]))
    slots = set()
    for k in range(3):
        r = step(sim, [S_RIGHT], [NOP])
        assert r.ammo[0, 0, 0] == 2 - k and not r.invalid.any()
        assert r.reward[0, 0] == R.valid_action
        slots |= set(np.flatnonzero(r.bullet_live[0]).tolist())
    assert len(slots) == 3  # each shot its own bullet
    r = step(sim, [S_RIGHT], [NOP])
    assert r.invalid[0, 0, 0] and not r.invalid[0, 1, 0]
    assert r.ammo[0, 0, 0] == 0 and r.reward[0, 0] == R.invalid
    assert sorted(bullets(r, 0)) == [(5, 1, 3), (6, 1, 3), (7, 1, 3)]  # nothing new on (4,1)
    r = step(sim, [S_LEFT], [NOP])
    assert r.invalid[0, 0, 0] and sorted(bullets(r, 0)) == [(6, 1, 3), (7, 1, 3)]


def test_dead_agents_queued_actions_ignored(start):
    sim = start(make(red=[(1, 4), (6, 6)], blue=[(3, 4), (0, 7)], mountains=[(3, 5)]))
    step(sim, [S_RIGHT, NOP], [NOP, NOP])
    step(sim, [NOP, NOP], [NOP, NOP])
    # Blue 0 queues a shot at red 0; red's bullet reaches (3,4) first (phase 1), so the shot never happens.
    r = step(sim, [NOP, NOP], [S_LEFT, NOP])
    assert not r.alive[0, 1, 0]
    assert r.ammo[0, 1, 0] == 3 and bullets(r, 1) == [] and not r.invalid[0, 1, 0]
    assert r.agent_reward[0, 1, 0] == R.got_shot
    # Nothing a dead agent queues has an effect: not a move, not an unsafe move into the mountain above
    # it, not a shot.
    for action in (LEFT, UP, S_DOWN, DOWN):
        r = step(sim, [NOP, NOP], [action, NOP])
        assert pos(r, 1, 0) == (3, 4) and r.ammo[0, 1, 0] == 3
        assert not r.unsafe[0, 1, 0] and not r.invalid[0, 1, 0] and r.agent_reward[0, 1, 0] == 0.0
        assert bullets(r, 1) == [] and not r.alive[0, 1, 0]
    assert r.reward[0, 1] == R.valid_action  # only the living blue agent pays


def test_base_capture_by_one_of_several_agents(start):
    sim = start(make(red=[(7, 0), (4, 1), (1, 7)], blue=[(0, 7), (0, 6), (2, 2)]))
    r = step(sim, [NOP, UP, LEFT], [NOP, NOP, NOP])
    assert pos(r, 0, 2) == (0, 7)
    assert r.terminated[0] and r.winner[0] == WINNER_RED
    assert r.reward[0, 0] == 3 * R.valid_action + R.win
    assert r.reward[0, 1] == 3 * R.valid_action + R.loss
    assert r.agent_reward[0, 0].tolist() == [R.valid_action + R.win] * 3


def test_capture_and_elimination_in_same_step(start):
    # Red 0 walks onto the blue base while red 1's bullet kills both blue agents (sharing a cell):
    # red wins once, by both rules.
    sim = start(make(red=[(3, 7), (5, 3)], blue=[(5, 5), (5, 5)]))
    step(sim, [LEFT, S_UP], [NOP, NOP])
    r = step(sim, [LEFT, NOP], [NOP, NOP])
    assert r.alive[0, 1].all() and not r.done[0]
    r = step(sim, [LEFT, NOP], [NOP, NOP])
    assert pos(r, 0, 0) == (0, 7) and not r.alive[0, 1].any()
    assert r.winner[0] == WINNER_RED and r.terminated[0]
    assert r.reward[0, 0] == 2 * R.valid_action + 2 * R.hit_opponent + R.win
    assert r.reward[0, 1] == 2 * R.got_shot + R.loss


def test_both_teams_capture_in_same_step_is_a_draw(start):
    sim = start(make(red=[(1, 7)], blue=[(6, 0)]))
    r = step(sim, [LEFT], [RIGHT])
    assert r.winner[0] == WINNER_DRAW and r.terminated[0]
    assert r.reward[0].tolist() == [R.valid_action, R.valid_action]


def test_capture_attempt_killed_by_walk_in_hit_loses_by_elimination(start):
    sim = start(make(red=[(2, 7)], blue=[(0, 6)]))
    step(sim, [LEFT], [S_UP])  # blue's bullet on (0,6); red to (1,7)
    r = step(sim, [LEFT], [NOP])  # bullet -> (0,7), the blue base; red walks into it
    assert not r.alive[0, 0, 0] and pos(r, 0) == (0, 7)
    assert r.winner[0] == WINNER_BLUE  # a dead agent captures nothing; red is eliminated


def test_step_limit_truncation(start):
    sim = start(make(red=[(7, 0)], blue=[(0, 7)], max_steps=5))
    for k in range(4):
        r = step(sim, [NOP], [NOP])
        assert not r.done[0]
    r = step(sim, [NOP], [NOP])
    assert r.truncated[0] and not r.terminated[0] and r.winner[0] == WINNER_NONE
    assert r.reward[0].tolist() == [R.valid_action, R.valid_action]  # truncation adds nothing
    r = step(sim, [LEFT], [DOWN])  # a finished world waits for reset
    assert r.t[0] == 5 and pos(r, 0) == (7, 0) and r.truncated[0]
    assert r.reward[0].tolist() == [0.0, 0.0]
    obs = sim.reset()
    assert sim.state.t[0] == 0 and not sim.state.truncated[0]
    assert obs[0, 0].tolist() == [7, 0, 0, 7, 0, -1, -1]


def test_many_agents_on_one_cell(start):
    sim = start(make(red=[(3, 1)] * 3, blue=[(3, 1)] * 3))
    r = step(sim, [UP] * 3, [UP] * 3)  # six agents share a cell, move together, no blocking
    assert all(pos(r, t, j) == (3, 2) for t in range(2) for j in range(3))
    r = step(sim, [S_LEFT, NOP, UP], [NOP] * 3)  # one point-blank bullet hits every enemy on the cell
    assert not r.alive[0, 1].any() and r.alive[0, 0].all()
    assert r.hits_made[0, 0].tolist() == [3, 0, 0] and r.hits_taken[0, 1].tolist() == [1, 1, 1]
    assert r.winner[0] == WINNER_RED
    assert r.agent_reward[0, 0, 0] == R.valid_action + 3 * R.hit_opponent + R.win


def test_bullet_entering_a_crowded_cell_hits_every_enemy_there(start):
    sim = start(make(red=[(1, 1), (3, 1), (3, 1)], blue=[(0, 7), (3, 1), (6, 6)]))
    step(sim, [S_RIGHT, NOP, NOP], [NOP, NOP, NOP])
    step(sim, [NOP, NOP, NOP], [NOP, NOP, NOP])
    r = step(sim, [NOP, NOP, NOP], [NOP, NOP, NOP])
    assert r.hits_taken[0, 1].tolist() == [0, 1, 0] and r.hits_taken[0, 0].sum() == 0
    assert r.hits_made[0, 0, 0] == 1 and bullets(r, 0) == []


def nonmarkov(red, blue, **kw) -> Scenario:
    return make(red=red, blue=blue, slow_agents=SlowAgents(red=[1], blue=[1]), **kw)


@pytest.mark.parametrize("sim_class, health", HEALTH_ROWS)
def test_slow_agent_two_step_move_interrupted_by_hit(start, health):
    # Blue 0 shoots right from (1,2); the bullet reaches (4,2) at step 3. Red's slow agent on (4,2)
    # starts moving up at step 2 and would arrive at step 3: the hit interrupts the move.
    sim = start(nonmarkov(red=[(7, 0), (4, 2)], blue=[(1, 2), (0, 7)], health=health))
    step(sim, [NOP, NOP], [S_RIGHT, NOP])
    step(sim, [NOP, NOP], [NOP, NOP])
    r = step(sim, [NOP, UP], [NOP, NOP])
    assert r.moving[0, 0, 1] and pos(r, 0, 1) == (4, 2)  # in transit, still on its source cell
    assert r.move_dest[0, 0, 1].tolist() == [4, 3] and (r.move_dest[0, 0, 0] == -1).all()
    r = step(sim, [NOP, NOP], [NOP, NOP])
    assert r.hits_taken[0, 0, 1] == 1 and not r.moving[0, 0, 1]
    assert pos(r, 0, 1) == (4, 2)  # it never arrives
    assert r.alive[0, 0, 1] == (health == 2.0)
    if health == 2.0:
        r = step(sim, [NOP, UP], [NOP, NOP])  # step 4: it may act again
        assert r.moving[0, 0, 1]
        r = step(sim, [NOP, NOP], [NOP, NOP])
        assert pos(r, 0, 1) == (4, 3) and not r.moving[0, 0, 1]


def test_slow_agent_moves_take_two_steps_and_it_acts_on_even_steps_only(start):
    sim = start(nonmarkov(red=[(7, 0), (5, 2)], blue=[(0, 7), (1, 5)]))
    r = step(sim, [LEFT, LEFT], [NOP, NOP])  # step 0: both set off
    assert pos(r, 0, 0) == (6, 0) and pos(r, 0, 1) == (5, 2) and r.moving[0, 0, 1]
    assert r.agent_reward[0, 0].tolist() == [R.valid_action, R.valid_action]
    obs = observe(sim.state, "red", sim.scenario)
    assert obs[0, 2:4].tolist() == [5, 2]  # observed on the source cell until arrival
    r = step(sim, [LEFT, S_UP], [NOP, NOP])  # step 1: arrives; the queued shot is ignored
    assert pos(r, 0, 1) == (4, 2) and not r.moving[0, 0, 1]
    assert r.ammo[0, 0, 1] == 3 and r.agent_reward[0, 0, 1] == 0.0
    r = step(sim, [NOP, S_UP], [NOP, NOP])  # step 2: may act; a shot takes one step
    assert r.ammo[0, 0, 1] == 2 and bullets(r, 0) == [(4, 2, 0)]
    r = step(sim, [NOP, DOWN], [NOP, NOP])  # step 3: not its turn
    assert pos(r, 0, 1) == (4, 2) and not r.moving[0, 0, 1] and r.agent_reward[0, 0, 1] == 0.0
    # step 4: a move into a mountain is refused at once (no transit), like a fast agent's
    sim2 = start(nonmarkov(red=[(7, 0), (5, 2)], blue=[(0, 7), (1, 5)], mountains=[(5, 3)]))
    r = step(sim2, [NOP, UP], [NOP, NOP])
    assert r.unsafe[0, 0, 1] and not r.moving[0, 0, 1] and pos(r, 0, 1) == (5, 2)
    assert r.agent_reward[0, 0, 1] == R.unsafe


def test_slow_agent_arriving_on_a_bullet_is_hit(start):
    # The arrival is a move: arriving on a cell that holds an enemy bullet is a walk-in hit.
    sim = start(nonmarkov(red=[(4, 4), (7, 0)], blue=[(0, 7), (3, 3)]))
    r = step(sim, [S_DOWN, NOP], [NOP, RIGHT])  # red bullet on (4,4), heading down; blue slow sets off
    assert r.moving[0, 1, 1] and r.alive[0, 1, 1]
    r = step(sim, [NOP, NOP], [NOP, NOP])       # bullet -> (4,3), then blue slow arrives on (4,3)
    assert pos(r, 1, 1) == (4, 3) and not r.alive[0, 1, 1]
    assert r.hits_made[0, 0, 0] == 1 and bullets(r, 0) == []


@pytest.mark.parametrize("sim_class, health", HEALTH_ROWS)
def test_slow_agent_hit_as_it_sets_off_does_not_move(start, health):
    # With health 2 it survives the hit and stays; with health 1 it dies where it stood.
    sim = start(nonmarkov(red=[(7, 0), (4, 2)], blue=[(0, 7), (4, 2)], health=health))
    r = step(sim, [NOP, UP], [NOP, S_LEFT])  # point blank on its cell as it leaves
    assert r.hits_taken[0, 0, 1] == 1 and not r.moving[0, 0, 1]
    assert (r.move_dest[0, 0, 1] == -1).all() and r.alive[0, 0, 1] == (health == 2.0)
    r = step(sim, [NOP, NOP], [NOP, NOP])
    assert pos(r, 0, 1) == (4, 2) and not r.moving[0, 0, 1]


# ----------------------------------------------------------------------------------------------------
# Other rules of the step
# ----------------------------------------------------------------------------------------------------
def test_unsafe_moves_are_shielded_and_penalised(start):
    sim = start(make(red=[(7, 1)], blue=[(0, 6)], mountains=[(6, 1)]))
    r = step(sim, [LEFT], [LEFT])  # into a mountain; off the map
    assert pos(r, 0) == (7, 1) and pos(r, 1) == (0, 6)
    assert r.unsafe[0, :, 0].tolist() == [True, True]
    assert r.reward[0].tolist() == [R.unsafe, R.unsafe]
    r = step(sim, [RIGHT], [NOP])
    assert r.unsafe[0, 0, 0] and r.reward[0, 1] == R.valid_action


def test_several_hits_to_kill_count_across_steps_and_phases(start):
    # health 1, damage 0.4: three hits kill. Blue stands on red's cell; red shoots point blank three
    # times: health 0.6, then 0.2, then dead (and the trace of the rules counts each hit)
    sim = start(make(red=[(3, 1)], blue=[(3, 1)], health=1.0, damage=0.4))
    r = step(sim, [S_UP], [NOP])
    assert r.alive[0, 1, 0] and r.health[0, 1, 0] == 1.0 - 0.4 and r.hits_taken[0, 1, 0] == 1
    r = step(sim, [S_DOWN], [NOP])
    assert r.alive[0, 1, 0] and r.health[0, 1, 0] == (1.0 - 0.4) - 0.4
    r = step(sim, [S_LEFT], [NOP])
    assert not r.alive[0, 1, 0] and r.health[0, 1, 0] == 0.0 and r.winner[0] == WINNER_RED


def test_damage_above_health_kills_with_one_hit(start):
    # damage > health is allowed in both simulators: health goes to exactly 0, not below.
    sim = start(make(red=[(3, 1)], blue=[(3, 1)], health=2.0, damage=3.0))
    r = step(sim, [S_UP], [NOP])
    assert r.health[0].tolist() == [[2.0], [0.0]] and r.alive[0].tolist() == [[True], [False]]
    assert r.winner[0] == WINNER_RED


def test_actions_outside_the_scenario_are_rejected(start):
    sim = start(make(red=[(7, 0)], blue=[(0, 7)], advanced=False))
    with pytest.raises(ValueError, match="action 4 of red agent 0"):
        step(sim, [S_UP], [NOP])
    with pytest.raises(ValueError, match="action 9 of blue agent 0"):
        step(sim, [NOP], [9])
    assert sim.state.t[0] == 0  # nothing happened
    with pytest.raises(ValueError, match="shape"):
        sim.step(np.zeros((1, 2), int), np.zeros((1, 1), int))
    r = step(sim, [UP], [NOP])  # and the game goes on as if the bad calls never came
    assert r.t[0] == 1 and pos(r, 0) == (7, 1) and pos(r, 1) == (0, 7) and not r.unsafe.any()


def test_rewards_are_configurable(start):
    from tracelab.game.scenario import Rewards
    sim = start(make(red=[(3, 1)], blue=[(3, 1)], rewards=Rewards(hit_opponent=1, got_shot=-3, valid_action=0,
                                                                   win=10, loss=-20)))
    r = step(sim, [S_UP], [NOP])
    assert r.reward[0].tolist() == [1 + 10, -3 - 20]


def test_observations_layout_and_sentinels(start):
    sim = start(make(red=[(6, 1), (5, 5)], blue=[(1, 6), (6, 4)]))
    obs = observe(sim.state, "red", sim.scenario)
    assert obs.shape == (1, 14) == (1, obs_size(sim.scenario))
    assert obs[0, :8].tolist() == [6, 1, 5, 5, 1, 6, 6, 4]  # own team first, then opponents
    assert obs[0, 8:].tolist() == [0, -1, -1] * 2  # no opponent bullet: count 0, sentinel position
    r = step(sim, [NOP, NOP], [S_DOWN, S_LEFT])  # blue bullets at (1,6) and (6,4)
    red = r.obs[0, 0]
    assert red[8:].tolist() == [2, 6, 4, 2, 6, 4]  # nearest to (6,1) is (6,4); to (5,5) also (6,4)
    blue = r.obs[0, 1]
    assert blue[:8].tolist() == [1, 6, 6, 4, 6, 1, 5, 5] and blue[8:].tolist() == [0, -1, -1] * 2
    r = step(sim, [NOP, NOP], [NOP, NOP])  # (6,4) bullet moves left to (5,4) ... and hits nothing
    r = step(sim, [NOP, NOP], [NOP, NOP])
    # Bullets now at (1,4) and (4,4): nearest to red 0 at (6,1) is (4,4) (distance 5 against 8).
    assert r.obs[0, 0, 8:11].tolist() == [2, 4, 4]
    # A dead agent reports (-1, -1), and so does its nearest-bullet entry.
    state = sim.state.copy()
    state.alive[0, 0, 1] = False
    obs = observe(state, "red", sim.scenario)
    assert obs[0, 2:4].tolist() == [-1, -1] and obs[0, 11:14].tolist() == [2, -1, -1]
    assert observe(state, "blue", sim.scenario)[0, 4:8].tolist() == [6, 1, -1, -1]


def test_nearest_bullet_ties_go_to_the_lowest_slot():
    from tracelab.game.state import GameState
    sc = make(red=[(3, 3)], blue=[(0, 7)])
    state = GameState.initial(sc, 1)
    # Blue's slots are 3, 4, 5 (red's come first). Two bullets at distance 2 from red, one further.
    state.bullet_pos[0, 3:6] = [(3, 6), (5, 3), (1, 3)]
    state.bullet_dir[0, 3:6] = [1, 2, 3]
    assert observe(state, "red", sc)[0, 4:].tolist() == [3, 5, 3]
    state.bullet_pos[0, 3] = (3, 4)
    assert observe(state, "red", sc)[0, 4:].tolist() == [3, 3, 4]
    assert observe(state, "red", sc, history=np.zeros((1, 7)))[0, 7:].tolist() == [0] * 7


def test_base_observation_has_four_numbers_per_agent(start):
    s = builtin_scenario("base")
    obs = start(s).reset()
    assert obs.shape == (1, 2, 4)
    assert obs[0, 0].tolist() == [7, 0, 0, 7] and obs[0, 1].tolist() == [0, 7, 7, 0]


def test_non_markov_observation_appends_previous(start):
    sim = start(builtin_scenario("nonmarkov"), stack_previous=True)
    obs0 = sim.reset().copy()  # kept past the next step, which overwrites the simulator's buffers
    assert obs0.shape == (1, 2, 28) and sim.obs_size == 28
    assert np.array_equal(obs0[..., :14], obs0[..., 14:])  # at reset the previous is the current
    r = step(sim, [UP, UP], [DOWN, RIGHT]).copy()
    assert np.array_equal(r.obs[..., 14:], obs0[..., :14])
    assert r.obs[0, 0, :4].tolist() == [7, 1, 7, 0]  # fast agent moved; slow one still in transit
    r2 = step(sim, [UP, NOP], [DOWN, NOP])
    assert np.array_equal(r2.obs[..., 14:], r.obs[..., :14])
    assert r2.obs[0, 0, :4].tolist() == [7, 2, 7, 1]
    assert np.array_equal(sim.observe("blue"), r2.obs[:, 1])


# ----------------------------------------------------------------------------------------------------
# Batches, resets and invariants
# ----------------------------------------------------------------------------------------------------
def rollout_actions(scenario: Scenario, n_worlds: int, steps: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Scripted actions for both teams, recorded from a batched run (the recorded stream is replayed)."""
    sim = RefSim(scenario, n_worlds, seed=seed)
    sim.reset()
    out = []
    for _ in range(steps):
        acts = (sim.scripted_actions("red"), sim.scripted_actions("blue"))
        out.append(acts)
        sim.step(*acts)
    return out


def test_batched_worlds_match_single_worlds(sim_class):
    scenario = generate_scenario(10, 10, 3, 0.15, seed=3, advanced=True)
    n_worlds = 12
    steps = 40
    acts = rollout_actions(scenario, n_worlds, steps, seed=5)
    batch = sim_class(scenario, n_worlds)
    batch.reset()
    singles = [sim_class(scenario) for _ in range(n_worlds)]
    for s in singles:
        s.reset()
    for red, blue in acts:
        rb = batch.step(red, blue)
        for w, s in enumerate(singles):
            rs = s.step(red[w:w + 1], blue[w:w + 1])
            for name in ("obs", "positions", "health", "ammo", "alive", "moving", "move_dest", "bullet_pos",
                         "bullet_dir", "unsafe", "invalid", "hits_made", "hits_taken", "agent_reward", "reward",
                         "terminated", "truncated", "winner", "t"):
                assert np.array_equal(getattr(rb, name)[w], getattr(rs, name)[0]), (name, w)
    assert rb.hits_made.sum() >= 0 and batch.state.ammo.sum() < 2 * 3 * 3 * n_worlds  # shots happened


def test_random_rollouts_keep_the_invariants(sim_class):
    scenario = generate_scenario(12, 12, 5, 0.2, seed=11, advanced=True)
    n_worlds = 64
    grid = scenario.mountain_grid
    sim = sim_class(scenario, n_worlds, seed=2)
    sim.reset()
    ends = 0
    for _ in range(300):
        done_before = sim.state.done.copy()
        r = sim.step(sim.scripted_actions("red"), sim.scripted_actions("blue"))
        assert not grid[r.positions[..., 0], r.positions[..., 1]].any()  # nobody on a mountain
        assert np.array_equal(r.alive, r.health > 0) and (r.health >= 0).all()
        live = r.bullet_live
        assert not grid[r.bullet_pos[live][:, 0], r.bullet_pos[live][:, 1]].any()
        # No living agent ever ends a step on a cell with an enemy bullet.
        for w in range(n_worlds):
            for b in np.flatnonzero(live[w]):
                enemy = 1 - r.bullet_owner[b, 0]
                on_cell = (r.positions[w, enemy] == r.bullet_pos[w, b]).all(axis=1) & r.alive[w, enemy]
                assert not on_cell.any()
        # An agent's k-th shot has its own slot: only the slots of shots already fired can be live.
        fired = (3 - r.ammo)[:, r.bullet_owner[:, 0], r.bullet_owner[:, 1]]  # [W, B]
        shot_number = np.arange(r.bullet_dir.shape[1]) % 3
        assert (fired >= 0).all() and (~live | (shot_number < fired)).all()
        assert (r.winner[r.terminated] != WINNER_NONE).all() and (r.winner[~r.done] == WINNER_NONE).all()
        assert (r.reward[done_before] == 0).all()
        ends += int((r.done & ~done_before).sum())
        if r.done.any():
            sim.reset(worlds=r.done)
    assert ends > 20


def test_reset_selected_worlds_only(start):
    sim = start(builtin_scenario("base"), 3)
    step_all = lambda a: sim.step(np.full((3, 1), a), np.full((3, 1), 8))  # noqa: E731
    step_all(UP)
    obs = sim.reset(worlds=np.array([False, True, False]))
    assert sim.state.t.tolist() == [1, 0, 1]
    assert obs[:, 0, :2].tolist() == [[7, 1], [7, 0], [7, 1]]


# ----------------------------------------------------------------------------------------------------
# The scripted policy
# ----------------------------------------------------------------------------------------------------
def one_agent_state(red_xy, blue_xy, n_worlds=1, ammo=3, alive=True):
    positions = np.zeros((n_worlds, 2, 1, 2), dtype=np.int64)
    positions[:, 0, 0] = red_xy
    positions[:, 1, 0] = blue_xy
    alive_arr = np.ones((n_worlds, 2, 1), dtype=bool)
    alive_arr[:, 0] = alive
    return positions, alive_arr, np.full((n_worlds, 2, 1), ammo)


def test_scripted_policy_moves_toward_enemy_base_about_70_percent():
    s = builtin_scenario("base")
    n = 40000
    acts = scripted_actions(*one_agent_state((7, 0), (0, 7), n), "blue", s, np.random.default_rng(0))
    counts = np.bincount(acts.ravel(), minlength=9) / n
    # From (0,7) down and right reduce the distance to (7,0). p = 0.7 picks one of them; the uniform
    # random 30% over 5 actions adds 2/5 of 0.3: 0.82 in all, split evenly.
    assert abs(counts[DOWN] + counts[RIGHT] - (0.7 + 0.3 * 2 / 5)) < 0.01
    assert abs(counts[DOWN] - counts[RIGHT]) < 0.015
    for a in (UP, LEFT, NOP):
        assert abs(counts[a] - 0.3 / 5) < 0.006
    assert counts[4:8].sum() == 0  # no shots in the base scenario


def test_scripted_policy_single_reducing_move_and_blocked_moves():
    s = make(red=[(7, 0)], blue=[(1, 7)], mountains=[(2, 7)], advanced=False)
    n = 40000
    acts = scripted_actions(*one_agent_state((7, 0), (1, 7), n), "blue", s, np.random.default_rng(1))
    counts = np.bincount(acts.ravel(), minlength=9) / n
    assert abs(counts[DOWN] - (0.7 + 0.3 / 5)) < 0.01  # right leads into a mountain: not a candidate
    assert abs(counts[RIGHT] - 0.3 / 5) < 0.006


def test_scripted_policy_with_no_reducing_move_is_uniform():
    s = make(red=[(7, 0)], blue=[(1, 7)], mountains=[(2, 7), (1, 6)], advanced=False)
    n = 40000
    acts = scripted_actions(*one_agent_state((7, 0), (1, 7), n), "blue", s, np.random.default_rng(2))
    counts = np.bincount(acts.ravel(), minlength=9) / n
    for a in (UP, DOWN, LEFT, RIGHT, NOP):
        assert abs(counts[a] - 0.2) < 0.01


def test_scripted_policy_shoots_when_in_line_with_ammo():
    s = builtin_scenario("advanced")
    rng = np.random.default_rng(3)
    n = 200
    column = scripted_actions(*one_agent_state((0, 2), (0, 7), n), "blue", s, rng)
    assert (column == S_DOWN).all()
    row = scripted_actions(*one_agent_state((5, 7), (0, 7), n), "blue", s, rng)
    assert (row == S_RIGHT).all()
    behind_mountain = scripted_actions(*one_agent_state((3, 1), (3, 6), n), "blue", s, rng)
    assert (behind_mountain == S_DOWN).all()  # "in line" ignores mountains (docs/game.md)
    same_cell = scripted_actions(*one_agent_state((3, 6), (3, 6), n), "blue", s, rng)
    assert (same_cell == S_UP).all()
    for no_shot in (one_agent_state((0, 2), (0, 7), n, ammo=0),        # no ammo left
                    one_agent_state((0, 2), (0, 7), n, alive=False)):  # enemy in line is dead
        acts = scripted_actions(*no_shot, "blue", s, rng)
        assert (acts == S_DOWN).mean() < 0.15 and np.isin(acts, [DOWN, RIGHT]).mean() > 0.6
    not_in_line = scripted_actions(*one_agent_state((5, 2), (0, 7), n), "blue", s, rng)
    assert np.isin(not_in_line, [DOWN, RIGHT]).mean() > 0.6


def test_scripted_policy_tie_breaking_between_enemies():
    s = make(red=[(7, 0)] * 3, blue=[(0, 7)] * 3)
    rng = np.random.default_rng(4)
    positions = np.zeros((1, 2, 3, 2), dtype=np.int64)
    alive = np.ones((1, 2, 3), dtype=bool)
    ammo = np.full((1, 2, 3), 3)
    positions[0, 1] = [(3, 3), (3, 3), (6, 6)]
    positions[0, 0] = [(3, 6), (0, 3), (3, 1)]  # up at 3, left at 3, down at 2: nearest wins
    assert scripted_actions(positions, alive, ammo, "blue", s, rng)[0, 0] == S_DOWN
    positions[0, 0] = [(3, 6), (0, 3), (7, 7)]  # up and left both at 3: lower action id (up)
    assert scripted_actions(positions, alive, ammo, "blue", s, rng)[0, 0] == S_UP
    alive[0, 0, 0] = False                      # dead enemies are no targets
    assert scripted_actions(positions, alive, ammo, "blue", s, rng)[0, 0] == S_LEFT
    alive[0, 1, 2] = False                      # and dead agents do nothing
    assert scripted_actions(positions, alive, ammo, "blue", s, rng)[0, 2] == NOP


def test_scripted_policy_works_for_either_team():
    s = make(red=[(5, 2)], blue=[(2, 5)], advanced=False)
    pos_, alive, ammo = one_agent_state((5, 2), (2, 5), 2000)
    red = scripted_actions(pos_, alive, ammo, "red", s, np.random.default_rng(5), p_toward=1.0)
    blue = scripted_actions(pos_, alive, ammo, "blue", s, np.random.default_rng(5), p_toward=1.0)
    assert set(red.ravel()) == {UP, LEFT}  # towards the blue base (0,7)
    assert set(blue.ravel()) == {DOWN, RIGHT}  # towards the red base (7,0)
    single = scripted_actions(pos_[0], alive[0], ammo[0], 0, s, np.random.default_rng(6))
    batch = scripted_actions(pos_[:1], alive[:1], ammo[:1], 0, s, np.random.default_rng(6))
    assert single.shape == (1,) and batch.shape == (1, 1) and single[0] == batch[0, 0]


def test_scripted_actions_are_reproducible_and_draw_a_fixed_amount():
    s = builtin_scenario("advanced")
    a, b = np.random.default_rng(9), np.random.default_rng(9)
    st1 = one_agent_state((7, 0), (0, 7), 50)
    st2 = one_agent_state((0, 2), (0, 7), 50)  # shoots: no randomness used, but the same draws
    assert np.array_equal(scripted_actions(*st1, "blue", s, a), scripted_actions(*st1, "blue", s, b))
    scripted_actions(*st1, "blue", s, a)
    scripted_actions(*st2, "blue", s, b)
    assert np.array_equal(scripted_actions(*st1, "blue", s, a), scripted_actions(*st1, "blue", s, b))


def test_scripted_blue_beats_an_idle_red_in_the_base_game(start):
    sim = start(builtin_scenario("base"), 64, seed=0)
    for _ in range(200):
        r = sim.step(np.full((64, 1), NOP), sim.scripted_actions("blue"))
    assert (r.winner == WINNER_BLUE).mean() > 0.95
