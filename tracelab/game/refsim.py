"""The reference simulator: the game of docs/game.md written directly, without the logic engine.

The rule-driven simulator is differentially tested against this one, so it follows the spec's
"one step, in order" literally, one phase after the other, in a numba kernel looping over worlds
(one call per batched step). All njit code lives in this module so numba's cache cannot go stale
through a changed callee elsewhere.

State layout (all arrays have a leading world axis W; team 0 = red, 1 = blue; N agents per team):
  pos [W,2,N,2] int32 (x, y), health [W,2,N] float64, ammo [W,2,N] int32, alive [W,2,N] bool,
  moving [W,2,N] bool and dest [W,2,N,2] (slow agents in transit), t [W] steps taken so far.
Bullets live in fixed slots: slot = (team * N + agent) * ammo0 + shot number, so B = 2 * N * ammo0 and
an agent's k-th bullet always has the same slot. bullet_pos [W,B,2] (-1,-1 when empty),
bullet_dir [W,B] int8 (0 up, 1 down, 2 left, 3 right, -1 empty).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .scenario import DEAD_EPS, Scenario
from .sim_base import GameSim
from .state import GameState, StepResult

_DX = np.array([0, 0, -1, 1], dtype=np.int64)
_DY = np.array([1, -1, 0, 0], dtype=np.int64)


# ----------------------------------------------------------------------------------------------------
# The step kernel
# ----------------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _remove_bullet(bpos, bdir, w, b):
    bdir[w, b] = -1
    bpos[w, b, 0] = -1
    bpos[w, b, 1] = -1


@njit(cache=True, inline="always")
def _bullet_hits(w, b, apos, eligible, alive, bpos, bdir, bteam, bagent, pending, hits_made):
    """Bullet b hits every living, eligible enemy of its owner standing on its cell (positions `apos`
    [2,N,2]); a bullet that hits is removed. Hits are only counted here (`pending`), applied later."""
    x = bpos[w, b, 0]
    y = bpos[w, b, 1]
    enemy = 1 - bteam[b]
    n_hit = 0
    for j in range(alive.shape[2]):
        if alive[w, enemy, j] and eligible[enemy, j] and apos[enemy, j, 0] == x and apos[enemy, j, 1] == y:
            pending[enemy, j] += 1
            n_hit += 1
    if n_hit > 0:
        hits_made[w, bteam[b], bagent[b]] += n_hit
        _remove_bullet(bpos, bdir, w, b)


@njit(cache=True, inline="always")
def _resolve_hits(w, pending, hit_now, health, alive, hits_taken, damage):
    """Apply the counted hits at once: each takes `damage`; at 0 health the agent dies."""
    for tm in range(2):
        for j in range(pending.shape[1]):
            k = pending[tm, j]
            hit_now[tm, j] = k > 0
            if k > 0:
                hits_taken[w, tm, j] += k
                health[w, tm, j] -= damage * k
                if health[w, tm, j] <= DEAD_EPS:
                    health[w, tm, j] = 0.0
                    alive[w, tm, j] = False
                pending[tm, j] = 0


@njit(cache=True)
def _step_kernel(actions, allowed, t, pos, health, ammo, alive, moving, dest, bpos, bdir,
                 terminated, truncated, winner, bteam, bagent, blocked, slow, bases, params,
                 max_steps, ammo0, unsafe, invalid, hits_made, hits_taken, agent_reward, reward):
    """One step of every unfinished world. Returns -1, or the flat index of the first action id the
    scenario does not offer (then nothing was changed)."""
    n_worlds = alive.shape[0]
    n = alive.shape[2]
    width, height = blocked.shape
    n_b = bdir.shape[1]
    damage, r_win, r_loss, r_hit, r_shot = params[0], params[1], params[2], params[3], params[4]
    r_valid, r_unsafe, r_invalid = params[5], params[6], params[7]

    for w in range(n_worlds):
        for tm in range(2):
            for j in range(n):
                a = actions[w, tm, j]
                if a < 0 or a >= allowed.shape[0] or not allowed[a]:
                    return (w * 2 + tm) * n + j

    pending = np.zeros((2, n), dtype=np.int64)
    hit_now = np.zeros((2, n), dtype=np.bool_)
    everyone = np.ones((2, n), dtype=np.bool_)
    moved = np.zeros((2, n), dtype=np.bool_)
    started = np.zeros((2, n), dtype=np.bool_)
    created = np.zeros(n_b, dtype=np.bool_)
    p0 = pos[0].copy()
    win = np.zeros(2, dtype=np.bool_)

    for w in range(n_worlds):
        if terminated[w] or truncated[w]:
            continue  # a finished world waits for reset
        step_no = t[w]

        # 1. Bullets already in flight advance one cell; mountains and the map edge remove them.
        for b in range(n_b):
            d = bdir[w, b]
            if d < 0:
                continue
            x = bpos[w, b, 0] + _DX[d]
            y = bpos[w, b, 1] + _DY[d]
            if x < 0 or x >= width or y < 0 or y >= height or blocked[x, y]:
                _remove_bullet(bpos, bdir, w, b)
                continue
            bpos[w, b, 0] = x
            bpos[w, b, 1] = y
            _bullet_hits(w, b, pos[w], everyone, alive, bpos, bdir, bteam, bagent, pending, hits_made)
        # 2. Hits resolve (all bullets of phase 1 at once).
        _resolve_hits(w, pending, hit_now, health, alive, hits_taken, damage)

        # 3. Living agents act, all at once: decisions read the positions before any move (p0).
        for tm in range(2):
            for j in range(n):
                p0[tm, j, 0] = pos[w, tm, j, 0]
                p0[tm, j, 1] = pos[w, tm, j, 1]
                moved[tm, j] = False
                started[tm, j] = False
        created[:] = False
        for tm in range(2):
            for j in range(n):
                if moving[w, tm, j]:
                    # Second step of a slow move: arrive, unless a hit in phase 2 interrupted it.
                    moving[w, tm, j] = False
                    if alive[w, tm, j] and not hit_now[tm, j]:
                        pos[w, tm, j, 0] = dest[w, tm, j, 0]
                        pos[w, tm, j, 1] = dest[w, tm, j, 1]
                        moved[tm, j] = True
                    dest[w, tm, j, 0] = -1
                    dest[w, tm, j, 1] = -1
                    continue
                if not alive[w, tm, j]:
                    continue  # dead agents' actions are ignored
                if slow[tm, j] and step_no % 2 == 1:
                    continue  # slow agents act on even steps only
                a = actions[w, tm, j]
                if a <= 3:
                    x = p0[tm, j, 0] + _DX[a]
                    y = p0[tm, j, 1] + _DY[a]
                    if x < 0 or x >= width or y < 0 or y >= height or blocked[x, y]:
                        unsafe[w, tm, j] = True  # shielded: the agent stays
                        agent_reward[w, tm, j] += r_unsafe
                    else:
                        agent_reward[w, tm, j] += r_valid
                        if slow[tm, j]:
                            moving[w, tm, j] = True  # leaves now, arrives next step
                            dest[w, tm, j, 0] = x
                            dest[w, tm, j, 1] = y
                            started[tm, j] = True
                        else:
                            pos[w, tm, j, 0] = x
                            pos[w, tm, j, 1] = y
                            moved[tm, j] = True
                elif a <= 7:
                    if ammo[w, tm, j] > 0:
                        slot = (tm * n + j) * ammo0 + (ammo0 - ammo[w, tm, j])
                        ammo[w, tm, j] -= 1
                        bpos[w, slot, 0] = p0[tm, j, 0]
                        bpos[w, slot, 1] = p0[tm, j, 1]
                        bdir[w, slot] = a - 4
                        created[slot] = True
                        agent_reward[w, tm, j] += r_valid
                    else:
                        invalid[w, tm, j] = True
                        agent_reward[w, tm, j] += r_invalid
                else:
                    agent_reward[w, tm, j] += r_valid
        # Point blank: a new bullet hits enemies that stood on the shooter's cell before moving.
        for b in range(n_b):
            if created[b]:
                _bullet_hits(w, b, p0, everyone, alive, bpos, bdir, bteam, bagent, pending, hits_made)
        _resolve_hits(w, pending, hit_now, health, alive, hits_taken, damage)
        for tm in range(2):
            for j in range(n):
                if started[tm, j] and hit_now[tm, j]:
                    moving[w, tm, j] = False  # hit as it sets off: the slow move is interrupted
                    dest[w, tm, j, 0] = -1
                    dest[w, tm, j, 1] = -1

        # 4. Walk-in hits: agents that moved onto a cell holding an enemy bullet (bullets are still now).
        for b in range(n_b):
            if bdir[w, b] >= 0:
                _bullet_hits(w, b, pos[w], moved, alive, bpos, bdir, bteam, bagent, pending, hits_made)
        _resolve_hits(w, pending, hit_now, health, alive, hits_taken, damage)

        # Rewards of hits (credited to a bullet's owner even if it died meanwhile).
        for tm in range(2):
            total = 0.0
            for j in range(n):
                agent_reward[w, tm, j] += hits_made[w, tm, j] * r_hit + hits_taken[w, tm, j] * r_shot
                total += agent_reward[w, tm, j]
            reward[w, tm] = total

        # 5. End of game: capture (a living agent on the enemy base) or elimination; both teams => draw.
        t[w] = step_no + 1
        win[0] = False
        win[1] = False
        for tm in range(2):
            n_alive = 0
            for j in range(n):
                if alive[w, tm, j]:
                    n_alive += 1
                    if pos[w, tm, j, 0] == bases[1 - tm, 0] and pos[w, tm, j, 1] == bases[1 - tm, 1]:
                        win[tm] = True
            if n_alive == 0:
                win[1 - tm] = True
        if win[0] or win[1]:
            terminated[w] = True
            if win[0] and win[1]:
                winner[w] = 2
            else:
                wt = 0 if win[0] else 1
                winner[w] = wt
                for tm in range(2):
                    term = r_win if tm == wt else r_loss
                    reward[w, tm] += term
                    for j in range(n):
                        agent_reward[w, tm, j] += term
        elif t[w] >= max_steps:
            truncated[w] = True
    return -1


# ----------------------------------------------------------------------------------------------------
# The simulator
# ----------------------------------------------------------------------------------------------------
class RefSim(GameSim):
    """The game in `n_worlds` independent worlds, stepped together.

    The dynamics are deterministic; `seed` drives `rng`, used by `scripted_actions()` (the scripted
    policy for either team). With `stack_previous`, observations are [current, previous] (at reset the
    previous observation is the current one).
    """

    def __init__(self, scenario: Scenario, n_worlds: int = 1, seed: int | None = None,
                 stack_previous: bool = False):
        super().__init__(scenario, n_worlds, seed, stack_previous)
        n = scenario.agents_per_team
        self._allowed = np.zeros(9, dtype=bool)
        self._allowed[list(scenario.action_ids)] = True
        self._blocked = np.ascontiguousarray(scenario.mountain_grid)
        self._slow = np.ascontiguousarray(scenario.slow_mask)
        self._bases = np.asarray(scenario.bases, dtype=np.int64)
        r = scenario.rewards
        self._params = np.array([scenario.damage, r.win, r.loss, r.hit_opponent, r.got_shot,
                                 r.valid_action, r.unsafe, r.invalid], dtype=np.float64)
        self._initial = GameState.initial(scenario, n_worlds)
        self.state = self._initial.copy()
        self._bullet_owner = np.stack([self.state.bullet_team, self.state.bullet_agent], axis=1).astype(np.int64)
        self._cur = self._current_obs()  # [W, 2, D] without history: the next step's "previous"
        self._obs = self._with_history(self._cur, self._cur)  # last observation handed out
        self._shape = (n_worlds, n)

    def reset(self, seed: int | None = None, worlds: np.ndarray | None = None) -> np.ndarray:
        """Start new episodes (in all worlds, or in the worlds of a mask / index array) and return the
        observations of every world, float32 [W, 2, D]."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        if worlds is None:
            self.state = self._initial.copy()
            worlds = slice(None)
        else:
            self.state.assign(self._initial, worlds)
        cur = self._current_obs()
        obs = self._obs.copy()  # never mutate an array a StepResult may hold
        obs[worlds] = self._with_history(cur, cur)[worlds]  # history at reset: the current obs
        self._cur, self._obs = cur, obs
        return obs.copy()

    def _current_obs(self) -> np.ndarray:
        return self._observe_both(self.state)

    def _actions(self, name: str, actions: np.ndarray) -> np.ndarray:
        a = np.asarray(actions, dtype=np.int64)
        if a.ndim == 1 and self.n_worlds == 1:
            a = a[None]
        if a.shape != self._shape:
            raise ValueError(f"{name} must have shape {self._shape} (worlds, agents), got {a.shape}")
        return a

    def step(self, red_actions: np.ndarray, blue_actions: np.ndarray) -> StepResult:
        """Advance every unfinished world by one step. Actions are spec ids, int [W, N] per team.
        Finished worlds do not change (zero rewards, flags kept) until reset."""
        acts = np.stack([self._actions("red_actions", red_actions),
                         self._actions("blue_actions", blue_actions)], axis=1)
        s = self.state
        finished_before = s.terminated | s.truncated
        n_worlds, n = self._shape
        unsafe = np.zeros((n_worlds, 2, n), dtype=bool)
        invalid = np.zeros((n_worlds, 2, n), dtype=bool)
        hits_made = np.zeros((n_worlds, 2, n), dtype=np.int32)
        hits_taken = np.zeros((n_worlds, 2, n), dtype=np.int32)
        agent_reward = np.zeros((n_worlds, 2, n), dtype=np.float64)
        reward = np.zeros((n_worlds, 2), dtype=np.float64)
        bad = _step_kernel(acts, self._allowed, s.t, s.pos, s.health, s.ammo, s.alive, s.moving, s.dest,
                           s.bullet_pos, s.bullet_dir, s.terminated, s.truncated, s.winner,
                           s.bullet_team, s.bullet_agent, self._blocked, self._slow, self._bases,
                           self._params, self.scenario.max_steps, self.scenario.ammo,
                           unsafe, invalid, hits_made, hits_taken, agent_reward, reward)
        if bad >= 0:
            w, tm, j = np.unravel_index(bad, acts.shape)
            raise ValueError(f"action {acts[w, tm, j]} of {('red', 'blue')[tm]} agent {j} in world {w} is "
                             f"not offered by scenario {self.scenario.name!r} (ids {self.scenario.action_ids})")
        cur = self._current_obs()
        obs = self._with_history(cur, self._cur)
        finished = finished_before  # a finished world's observation stays as it was, history included
        cur[finished] = self._cur[finished]
        obs[finished] = self._obs[finished]
        self._cur, self._obs = cur, obs
        return StepResult(
            obs=obs, positions=s.pos.copy(), health=s.health.copy(), ammo=s.ammo.copy(),
            alive=s.alive.copy(), moving=s.moving.copy(), move_dest=s.dest.copy(), bullet_pos=s.bullet_pos.copy(),
            bullet_dir=s.bullet_dir.copy(), bullet_owner=self._bullet_owner, unsafe=unsafe,
            invalid=invalid, hits_made=hits_made, hits_taken=hits_taken, agent_reward=agent_reward,
            reward=reward, terminated=s.terminated.copy(), truncated=s.truncated.copy(),
            winner=s.winner.copy(), t=s.t.copy())
