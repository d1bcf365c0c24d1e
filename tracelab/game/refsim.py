"""The reference simulator: the game of docs/game.md written directly, without the logic engine.

The spec (rules/gridworld/war*.toml) is differentially tested against this one (tests/test_gridwar_spec.py),
so it follows docs/game.md's "One step" literally, one phase after the other, in a numba kernel looping
over worlds (one call per batched step). All njit code lives in this module so numba's cache cannot go stale
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

from .observe import obs_size, observe_both, observe_step
from .opponent import P_TOWARD, TeamPolicy
from .scenario import DEAD_EPS, Scenario, team_index
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
def _step_kernel(red, blue, allowed, t, pos, health, ammo, alive, moving, dest, bpos, bdir,
                 terminated, truncated, winner, bteam, bagent, blocked, slow, bases, params,
                 max_steps, ammo0, unsafe, invalid, hits_made, hits_taken, agent_reward, reward, was_done):
    """One step of every unfinished world, in place; actions red, blue [W, N]. The step's events and
    rewards (unsafe .. reward) are written for every world (zero in finished ones); was_done[w]: the
    world was finished before the step. Returns -1, or the flat index in [W, 2, N] of the first action
    id the scenario does not offer (then nothing was changed)."""
    n_worlds = alive.shape[0]
    n = alive.shape[2]
    width, height = blocked.shape
    n_b = bdir.shape[1]
    damage, r_win, r_loss, r_hit, r_shot = params[0], params[1], params[2], params[3], params[4]
    r_valid, r_unsafe, r_invalid = params[5], params[6], params[7]

    for w in range(n_worlds):
        for tm in range(2):
            for j in range(n):
                a = red[w, j] if tm == 0 else blue[w, j]
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
        for tm in range(2):
            reward[w, tm] = 0.0
            for j in range(n):
                unsafe[w, tm, j] = False
                invalid[w, tm, j] = False
                hits_made[w, tm, j] = 0
                hits_taken[w, tm, j] = 0
                agent_reward[w, tm, j] = 0.0
        was_done[w] = terminated[w] or truncated[w]
        if was_done[w]:
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
                a = red[w, j] if tm == 0 else blue[w, j]
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
def read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of a buffer: what the simulator hands out (made once, valid until the next step or
    reset overwrites the buffer)."""
    v = a.view()
    v.flags.writeable = False
    return v


class RefSim:
    """The game in `n_worlds` independent worlds, stepped together.

    The dynamics are deterministic; `seed` drives `rng`, used by `scripted_actions()` (the scripted
    policy for either team, moving towards the enemy base with probability `opponent_p`). With
    `stack_previous`, observations are [current, previous] (at reset the previous observation is the
    current one).

    The step contract (the convention of batched RL envs): with `copy=False` (the default) the arrays of
    a StepResult and of reset()'s observation are read-only views of buffers the simulator owns and
    overwrites at its next step or reset; with `copy=True` every step and reset returns new arrays that
    nothing changes later.
    """

    def __init__(self, scenario: Scenario, n_worlds: int = 1, seed: int | None = None,
                 stack_previous: bool = False, copy: bool = False):
        if n_worlds < 1:
            raise ValueError(f"n_worlds must be at least 1, got {n_worlds}")
        self.scenario = scenario
        self.n_worlds = n_worlds
        self.stack_previous = stack_previous
        self.copy = copy
        self.rng = np.random.default_rng(seed)
        self.obs_size = obs_size(scenario, stack_previous)
        self.opponent_p = P_TOWARD
        self._policy = TeamPolicy(scenario, n_worlds)
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
        self.state = s = self._initial.copy()  # stepped and reset in place: the buffers handed out
        self._bullet_owner = np.stack([s.bullet_team, s.bullet_agent], axis=1).astype(np.int64)
        shape = (n_worlds, 2, n)
        # the step's events, rewritten by every step: unsafe, invalid, hits made / taken, rewards
        self._events = (np.zeros(shape, bool), np.zeros(shape, bool), np.zeros(shape, np.int32),
                        np.zeros(shape, np.int32), np.zeros(shape), np.zeros((n_worlds, 2)))
        self._was_done = np.zeros(n_worlds, bool)
        cur = observe_both(s, scenario)
        self._obs = self._with_history(cur, cur)  # [W, 2, D]: the observation buffer
        self._obs_view = read_only(self._obs)
        self._shape = (n_worlds, n)
        unsafe, invalid, hits_made, hits_taken, agent_reward, reward = (read_only(a) for a in self._events)
        self._result = StepResult(
            obs=self._obs_view, positions=read_only(s.pos), health=read_only(s.health), ammo=read_only(s.ammo),
            alive=read_only(s.alive), moving=read_only(s.moving), move_dest=read_only(s.dest),
            bullet_pos=read_only(s.bullet_pos), bullet_dir=read_only(s.bullet_dir),
            bullet_owner=read_only(self._bullet_owner), unsafe=unsafe, invalid=invalid, hits_made=hits_made,
            hits_taken=hits_taken, agent_reward=agent_reward, reward=reward, terminated=read_only(s.terminated),
            truncated=read_only(s.truncated), winner=read_only(s.winner), t=read_only(s.t))

    def reset(self, seed: int | None = None, worlds: np.ndarray | None = None) -> np.ndarray:
        """Start new episodes (in all worlds, or in the worlds of a mask / index array) and return the
        observations of every world, float32 [W, 2, D] (a buffer, unless copy=True)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        # indices taken first: the mask may be a view of this simulator's own flags, reset below
        sel = slice(None) if worlds is None else (
            np.flatnonzero(worlds) if np.asarray(worlds).dtype == bool else np.array(worlds))
        self.state.assign(self._initial, sel)
        # their observation becomes the start's (history at a reset: the current observation)
        cur = observe_both(self.state, self.scenario)
        self._obs[sel] = self._with_history(cur, cur)[sel]
        return self._obs.copy() if self.copy else self._obs_view

    def _with_history(self, cur: np.ndarray, prev: np.ndarray) -> np.ndarray:
        return np.concatenate([cur, prev], axis=2) if self.stack_previous else cur

    def observe(self, team: int | str) -> np.ndarray:
        """The last observation of one team (from reset or step), [W, D]."""
        return self._obs[:, team_index(team)].copy()

    def scripted_actions(self, team: int | str = "blue") -> np.ndarray:
        """The scripted policy's actions for `team` in the current state, drawn from `self.rng` (new
        int64 [W, N])."""
        s = self.state
        return self._policy(s.pos, s.alive, s.ammo, team_index(team), self.rng, float(self.opponent_p))

    def _actions(self, name: str, actions: np.ndarray) -> np.ndarray:
        a = actions if type(actions) is np.ndarray and actions.dtype == np.int64 else np.asarray(actions, np.int64)
        if a.ndim == 1 and self.n_worlds == 1:
            a = a[None]
        if a.shape != self._shape:
            raise ValueError(f"{name} must have shape {self._shape} (worlds, agents), got {a.shape}")
        return a

    def step(self, red_actions: np.ndarray, blue_actions: np.ndarray) -> StepResult:
        """Advance every unfinished world by one step. Actions are spec ids, int [W, N] per team.
        Finished worlds do not change (zero rewards, flags kept) until reset."""
        red, blue = self._actions("red_actions", red_actions), self._actions("blue_actions", blue_actions)
        s = self.state
        unsafe, invalid, hits_made, hits_taken, agent_reward, reward = self._events
        bad = _step_kernel(red, blue, self._allowed, s.t, s.pos, s.health, s.ammo, s.alive, s.moving, s.dest,
                           s.bullet_pos, s.bullet_dir, s.terminated, s.truncated, s.winner,
                           s.bullet_team, s.bullet_agent, self._blocked, self._slow, self._bases,
                           self._params, self.scenario.max_steps, self.scenario.ammo,
                           unsafe, invalid, hits_made, hits_taken, agent_reward, reward, self._was_done)
        if bad >= 0:
            w, tm, j = np.unravel_index(bad, (self.n_worlds, 2, self._shape[1]))
            raise ValueError(f"action {(red, blue)[tm][w, j]} of {('red', 'blue')[tm]} agent {j} in world {w} "
                             f"is not offered by scenario {self.scenario.name!r} (ids {self.scenario.action_ids})")
        # a finished world's observation stays as it was, history included
        observe_step(s.pos, s.alive, s.bullet_pos, s.bullet_dir, s.bullet_team, self.scenario.advanced,
                     self.stack_previous, self._was_done, self._obs)
        return self._result.copy() if self.copy else self._result
