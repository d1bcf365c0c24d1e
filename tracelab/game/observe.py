"""Observations of the game state (docs/game.md): own and opponent positions per agent, and in the
advanced scenario the opponent's bullets. Both simulators observe through these functions; all njit
code of observations lives in this module so numba's cache cannot go stale through a callee elsewhere."""
from __future__ import annotations

import numpy as np
from numba import njit

from .scenario import Scenario, team_index
from .state import GameState

SENTINEL = -1.0          # observed x, y of a dead agent / of a missing bullet


# ----------------------------------------------------------------------------------------------------
# Observations
# ----------------------------------------------------------------------------------------------------
@njit(cache=True)
def _observe_world(w, team, pos, alive, bpos, bdir, bteam, advanced, live, out):
    """Fill out [D] with world w's observation of `team`: own then opponent (x, y) per agent; advanced:
    per own agent (opponent bullet count, nearest opponent bullet x, y). live [B] is scratch."""
    n = alive.shape[2]
    n_b = bdir.shape[1]
    enemy = 1 - team
    for k in range(2):
        tm = team if k == 0 else enemy
        for j in range(n):
            col = (k * n + j) * 2
            if alive[w, tm, j]:
                out[col] = pos[w, tm, j, 0]
                out[col + 1] = pos[w, tm, j, 1]
            else:
                out[col] = SENTINEL
                out[col + 1] = SENTINEL
    if not advanced:
        return
    # Gather the opponent's live bullets once; slot order breaks distance ties.
    count = 0
    for b in range(n_b):
        if bdir[w, b] >= 0 and bteam[b] == enemy:
            live[count] = b
            count += 1
    for j in range(n):
        col = 4 * n + 3 * j
        out[col] = count
        bx = SENTINEL
        by = SENTINEL
        if alive[w, team, j]:
            best = 1 << 40
            for i in range(count):
                b = live[i]
                d = abs(bpos[w, b, 0] - pos[w, team, j, 0]) + abs(bpos[w, b, 1] - pos[w, team, j, 1])
                if d < best:
                    best = d
                    bx = bpos[w, b, 0]
                    by = bpos[w, b, 1]
        out[col + 1] = bx
        out[col + 2] = by


@njit(cache=True)
def _observe_kernel(team, pos, alive, bpos, bdir, bteam, advanced, out):
    """Fill out [W, D] with every world's observation of `team`."""
    live = np.empty(bdir.shape[1], dtype=np.int64)
    for w in range(alive.shape[0]):
        _observe_world(w, team, pos, alive, bpos, bdir, bteam, advanced, live, out[w])


@njit(cache=True)
def _observe_both_kernel(pos, alive, bpos, bdir, bteam, advanced, out):
    """Fill out [W, 2, D] with both teams' observations."""
    for team in range(2):
        _observe_kernel(team, pos, alive, bpos, bdir, bteam, advanced, out[:, team])


@njit(cache=True)
def observe_step(pos, alive, bpos, bdir, bteam, advanced, history, keep, obs):
    """After a step, in place: obs [W, 2, D] (2D with `history`) becomes both teams' observation of the
    new state, with `history` the previous observation's current half moved to the history half first.
    Worlds with keep[w] (finished before the step) keep their observation, history included."""
    d = obs.shape[2]
    size = d // 2 if history else d
    live = np.empty(bdir.shape[1], dtype=np.int64)
    for w in range(alive.shape[0]):
        if keep[w]:
            continue
        for team in range(2):
            if size != d:
                for c in range(size):
                    obs[w, team, size + c] = obs[w, team, c]
            _observe_world(w, team, pos, alive, bpos, bdir, bteam, advanced, live, obs[w, team, :size])


def observe_both(state: GameState, scenario: Scenario) -> np.ndarray:
    """Both teams' observations without history, float32 [W, 2, D]."""
    out = np.empty((state.alive.shape[0], 2, obs_size(scenario)), dtype=np.float32)
    _observe_both_kernel(state.pos, state.alive, state.bullet_pos, state.bullet_dir, state.bullet_team,
                         scenario.advanced, out)
    return out


def obs_size(scenario: Scenario, stack_previous: bool = False) -> int:
    """Observation length per team: 4 (base) or 7 (advanced) per agent, doubled with history."""
    size = (7 if scenario.advanced else 4) * scenario.agents_per_team
    return 2 * size if stack_previous else size


def observe(state: GameState, team: int | str, scenario: Scenario,
            history: np.ndarray | None = None) -> np.ndarray:
    """Observation of `team` in every world: float32 [W, D]. With `history` (the previous step's
    observation without history, [W, D]) the result is [current, history], [W, 2D] (non-Markov setup)."""
    n_worlds = state.alive.shape[0]
    out = np.empty((n_worlds, obs_size(scenario)), dtype=np.float32)
    _observe_kernel(team_index(team), state.pos, state.alive, state.bullet_pos, state.bullet_dir,
                    state.bullet_team, scenario.advanced, out)
    if history is None:
        return out
    return np.concatenate([out, np.asarray(history, dtype=np.float32)], axis=1)
