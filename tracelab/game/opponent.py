"""The scripted base policy of the spec ("Opponent (blue) base policy"), for either team.

It is a function of plain state arrays, RefSim's (the hand-written simulator); the spec's opponent
(rules/gridworld/opponent.rules, its draws in this order) plays the same actions from the same seed.
Decisions (docs/game.md, "Scripted policy"):

- Shooting (advanced scenario, ammo > 0) comes first: among the *living* enemies in the same row or
  column, it shoots towards the nearest (Manhattan distance); a tie between enemies in different
  directions goes to the lower action id (shoot up < down < left < right). Mountains do not block this
  test (the spec says "in line (same row or column)"). An enemy on the agent's own cell is in line in
  every direction, so the agent shoots up (the bullet hits point blank whatever its direction).
- Otherwise, with probability p_toward (0.7) a move towards the enemy base: the moves whose target cell
  is on the map, not a mountain, and strictly closer (Manhattan) to the enemy base; uniform among them.
  If there is none, or with probability 1 - p_toward, a uniformly random action of the scenario's
  action set (shots included in the advanced scenario, even with no ammo left).
- Dead agents get NOTHING (8).
- Every call draws exactly three arrays of shape [worlds, agents] from the generator, whatever the
  state, so the random stream stays aligned between simulators.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from numba import njit

from . import scenario as _scenario
from .scenario import Scenario, team_index

P_TOWARD = 0.7
# Literals, not imports: numba freezes globals into its disk cache, which only notices changes to this
# file. The check below catches a change of the action table elsewhere.
NOTHING, SHOOT_UP = 8, 4
if (NOTHING, SHOOT_UP) != (_scenario.NOTHING, _scenario.SHOOT_UP):
    raise ImportError("opponent.py's action ids disagree with scenario.py")
_DX = np.array([0, 0, -1, 1], dtype=np.int64)  # up, down, left, right (scenario.DIRECTION_DELTAS)
_DY = np.array([1, -1, 0, 0], dtype=np.int64)


@njit(cache=True)
def _policy_kernel(pos, alive, ammo, team, draws, action_ids, blocked, goal, advanced, p_toward, out):
    """The policy for every agent of `team` in every world; draws [3, W, N] are its pre-drawn uniform
    numbers: toward-or-random, which closer move, which random action."""
    u, r, k = draws[0], draws[1], draws[2]
    n_worlds, _, n = alive.shape
    width, height = blocked.shape
    enemy = 1 - team
    gx, gy = goal[0], goal[1]
    for w in range(n_worlds):
        for j in range(n):
            if not alive[w, team, j]:
                out[w, j] = NOTHING
                continue
            x = pos[w, team, j, 0]
            y = pos[w, team, j, 1]
            if advanced and ammo[w, team, j] > 0:
                best_key = -1
                for e in range(n):
                    if not alive[w, enemy, e]:
                        continue
                    dx = pos[w, enemy, e, 0] - x
                    dy = pos[w, enemy, e, 1] - y
                    if dx != 0 and dy != 0:
                        continue  # not in line
                    if dx == 0:
                        d = 0 if dy >= 0 else 1  # same cell counts as "up"
                    else:
                        d = 2 if dx < 0 else 3
                    key = (abs(dx) + abs(dy)) * 4 + d  # nearest, then the lower action id
                    if best_key < 0 or key < best_key:
                        best_key = key
                if best_key >= 0:
                    out[w, j] = SHOOT_UP + best_key % 4
                    continue
            dist = abs(x - gx) + abs(y - gy)
            n_closer = 0
            for d in range(4):
                tx = x + _DX[d]
                ty = y + _DY[d]
                if 0 <= tx < width and 0 <= ty < height and not blocked[tx, ty] \
                        and abs(tx - gx) + abs(ty - gy) < dist:
                    n_closer += 1
            if u[w, j] < p_toward and n_closer > 0:
                pick = min(int(r[w, j] * n_closer), n_closer - 1)
                for d in range(4):
                    tx = x + _DX[d]
                    ty = y + _DY[d]
                    if 0 <= tx < width and 0 <= ty < height and not blocked[tx, ty] \
                            and abs(tx - gx) + abs(ty - gy) < dist:
                        if pick == 0:
                            out[w, j] = d
                            break
                        pick -= 1
            else:
                out[w, j] = action_ids[min(int(k[w, j] * action_ids.shape[0]), action_ids.shape[0] - 1)]


@lru_cache(maxsize=256)
def _int_array(values: tuple[int, ...]) -> np.ndarray:
    """A read-only int64 array of a small tuple, made once (made per call, it would cost a measurable
    share of a step: docs/benchmarks.md, "Figures behind the code")."""
    a = np.asarray(values, dtype=np.int64)
    a.flags.writeable = False
    return a


def scripted_actions(positions: np.ndarray, alive: np.ndarray, ammo: np.ndarray, team: int | str,
                     scenario: Scenario, rng: np.random.Generator, p_toward: float = P_TOWARD) -> np.ndarray:
    """Actions (spec ids) of `team`'s agents.

    positions: int [W, 2, N, 2] (x, y) indexed [world, team, agent] (or [2, N, 2] for one world),
    alive: bool [W, 2, N], ammo: int [W, 2, N]. Returns int64 [W, N] (or [N]).
    """
    # no dtype conversion (a copy per call): the kernel compiles for the simulators' int32 state as is
    pos = np.ascontiguousarray(positions)
    alive = np.ascontiguousarray(alive, dtype=np.bool_)
    ammo = np.ascontiguousarray(ammo)
    single = pos.ndim == 3
    if single:
        pos, alive, ammo = pos[None], alive[None], ammo[None]
    if pos.shape[-1] != 2 or pos.shape[:3] != alive.shape or ammo.shape != alive.shape or alive.shape[1] != 2:
        raise ValueError(f"expected positions [W,2,N,2], alive and ammo [W,2,N]; got {pos.shape}, "
                         f"{alive.shape}, {ammo.shape}")
    t = team_index(team)
    n_worlds, _, n = alive.shape
    action_ids = _int_array(scenario.action_ids)
    # Always the same draws, whatever the state, so the stream stays aligned between simulators
    # (one call for all three: each generator call costs microseconds, a fair share of a step's budget:
    # docs/benchmarks.md, "Figures behind the code").
    draws = rng.random((3, n_worlds, n))
    out = np.empty((n_worlds, n), dtype=np.int64)
    _policy_kernel(pos, alive, ammo, t, draws, action_ids, np.ascontiguousarray(scenario.mountain_grid),
                   _int_array(tuple(scenario.bases[1 - t])), scenario.advanced, float(p_toward), out)
    return out[0] if single else out


class TeamPolicy:
    """scripted_actions for one simulator's batch, lean: the scenario's tables and the draws' buffer made
    once, the state arrays passed as the simulator keeps them (writable, so the kernel's one compiled
    signature serves). Draws the same numbers from the generator as scripted_actions."""

    def __init__(self, scenario: Scenario, n_worlds: int) -> None:
        n = scenario.agents_per_team
        self._action_ids = _int_array(scenario.action_ids)
        self._blocked = np.ascontiguousarray(scenario.mountain_grid)
        self._goals = tuple(_int_array(tuple(scenario.bases[1 - t])) for t in range(2))
        self._advanced = bool(scenario.advanced)
        self._draws = np.empty((3, n_worlds, n))
        self._shape = (n_worlds, n)

    def __call__(self, pos: np.ndarray, alive: np.ndarray, ammo: np.ndarray, team: int,
                 rng: np.random.Generator, p_toward: float) -> np.ndarray:
        """Actions (spec ids, a new int64 [W, N]) of team index `team` for state arrays [W, 2, N(, 2)]."""
        rng.random(out=self._draws)  # the same stream as rng.random((3, W, N))
        out = np.empty(self._shape, dtype=np.int64)
        _policy_kernel(pos, alive, ammo, team, self._draws, self._action_ids, self._blocked, self._goals[team],
                       self._advanced, p_toward, out)
        return out
