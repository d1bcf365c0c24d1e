"""Compiled I/O of the rule-driven simulator: actions to fact rows, and atoms back to game state.

Nothing here decides anything about the game: encode_actions turns chosen actions into external-fact
rows for the engine, read_back gathers the atoms the rules set into arrays. Kept apart from
engine/kernel.py on purpose: neither module calls into the other (numba's cache does not track callees
across modules).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from . import scenario as _scenario

# A literal, not an import: numba freezes globals into its disk cache, which only notices changes to this
# file. The check below catches a change of the threshold in scenario.py.
DEAD_EPS = 1e-9
if DEAD_EPS != _scenario.DEAD_EPS:
    raise ImportError("rulesim_kernel.py's DEAD_EPS disagrees with scenario.py")


@njit(cache=True)
def _put_row(ext_i, ext_f, k, atom, value, first_id):
    """Row k: atom set to [value, value], not static, external id first_id + k. Returns k + 1."""
    ext_i[k, 0] = atom
    ext_i[k, 1] = 0
    ext_i[k, 2] = first_id + k
    ext_f[k, 0] = value
    ext_f[k, 1] = value
    return k + 1


@njit(cache=True)
def encode_actions(red, blue, terminated, truncated, allowed, action_atoms, prev, first_id, ext_ptr, ext_i, ext_f):
    """Rows for the engine's external facts, grouped by world: each agent's chosen action atom becomes
    [1,1] and its previous one [0,0] when they differ. red, blue [W, N] spec ids (agent j of the M = 2N
    in action_atoms [M, 9] is red j, then blue j - N; -1: no atom); a finished world (terminated or
    truncated) does nothing; prev [W, M] atom ids, updated in place. Every action is checked against
    allowed (bool [9]) first: returns -1 - (its flat index in [W, 2, N]) for the first one not offered,
    having changed nothing; else the number of rows."""
    n_worlds, n = red.shape
    for w in range(n_worlds):
        for tm in range(2):
            for i in range(n):
                a = red[w, i] if tm == 0 else blue[w, i]
                if a < 0 or a > 8 or not allowed[a]:
                    return -1 - ((w * 2 + tm) * n + i)
    k = np.int64(0)  # not a literal 0: _put_row is compiled for one type of k (tests/test_first_run.py)
    for w in range(n_worlds):
        ext_ptr[w] = k
        done = terminated[w] or truncated[w]
        for j in range(2 * n):
            new = -1
            if not done:
                new = action_atoms[j, red[w, j] if j < n else blue[w, j - n]]
            old = prev[w, j]
            if new == old:
                continue
            if old >= 0:
                k = _put_row(ext_i, ext_f, k, old, 0.0, first_id)
            if new >= 0:
                k = _put_row(ext_i, ext_f, k, new, 1.0, first_id)
            prev[w, j] = new
    ext_ptr[n_worlds] = k
    return k


@njit(cache=True)
def _first_true(truth, w, ids, row):
    for c in range(ids.shape[1]):
        if truth[w, ids[row, c]]:
            return c
    return -1


@njit(cache=True)
def read_back(truth, agent_loc, cell_xy, agent_flags, dest_ids, bullet_loc, bullet_flags, dir_ids,
              hits, bullet_team, bullet_agent, win_ids, ammo0, damage, apply_hits, kind_hits, terminated,
              truncated, pos, health, alive, ammo, moving, dest, unsafe, invalid, acted, bpos, bdir, hits_made,
              hits_taken, win, was_done):
    """Gather the game state of every world from atoms into the given arrays, in place. truth [W, K]
    says which atoms are [1,1] in which world (Engine.is_true: [W, K]); the id arrays index its columns.
    agent_flags [M, 5]: atom ids of alive, moving, unsafe, invalid, canAct per agent (M = 2N); unsafe,
    invalid and acted [W, 2, N] receive the last three. bullet_flags [B, 2]: flying, spent.
    hits [3, B, N]: struck / blanked / caught atoms of bullet b on enemy e. win_ids [2]: won(T) per
    team (game.rules, section 6); win [W, 2] receives them.
    Health is the held health less `damage` per hit, the hits of each phase (arrival, point blank,
    walk-in) taken together and 0 at or below DEAD_EPS, as docs/game.md computes it (with apply_hits;
    else the step's events are not new, e.g. at the start, and health stays); a dead agent's is 0.
    kind_hits [2, N, 3] is scratch. A world already finished (terminated or truncated; was_done[w]
    receives that) keeps its state and has no events."""
    n_worlds = truth.shape[0]
    for w in range(n_worlds):
        was_done[w] = terminated[w] or truncated[w]
        if was_done[w]:
            _no_events(w, unsafe, invalid, acted, hits_made, hits_taken, win)
        else:
            _read_world(w, truth, agent_loc, cell_xy, agent_flags, dest_ids, bullet_loc, bullet_flags,
                        dir_ids, hits, bullet_team, bullet_agent, win_ids, ammo0, pos, alive, ammo, moving,
                        dest, unsafe, invalid, acted, bpos, bdir, hits_made, hits_taken, win, kind_hits)
            _health(w, damage, apply_hits, kind_hits, alive, health)


@njit(cache=True)
def _no_events(w, unsafe, invalid, acted, hits_made, hits_taken, win):
    for tm in range(2):
        win[w, tm] = False
        for i in range(unsafe.shape[2]):
            hits_made[w, tm, i] = 0
            hits_taken[w, tm, i] = 0
            unsafe[w, tm, i] = False
            invalid[w, tm, i] = False
            acted[w, tm, i] = False


@njit(cache=True)
def _read_world(w, truth, agent_loc, cell_xy, agent_flags, dest_ids, bullet_loc, bullet_flags, dir_ids,
                hits, bullet_team, bullet_agent, win_ids, ammo0, pos, alive, ammo, moving, dest, unsafe,
                invalid, acted, bpos, bdir, hits_made, hits_taken, win, kind_hits):
    m = agent_loc.shape[0]
    n = m // 2
    for j in range(m):
        tm = j // n
        i = j % n
        c = _first_true(truth, w, agent_loc, j)
        # no cell at all would be a broken rule: (-1, -1) shows it instead of reading cell_xy[-1]
        pos[w, tm, i, 0] = cell_xy[c, 0] if c >= 0 else -1
        pos[w, tm, i, 1] = cell_xy[c, 1] if c >= 0 else -1
        alive[w, tm, i] = truth[w, agent_flags[j, 0]]
        for kind in range(3):
            kind_hits[tm, i, kind] = 0
        moving[w, tm, i] = truth[w, agent_flags[j, 1]]
        unsafe[w, tm, i] = truth[w, agent_flags[j, 2]]
        invalid[w, tm, i] = truth[w, agent_flags[j, 3]]
        acted[w, tm, i] = truth[w, agent_flags[j, 4]]
        dest[w, tm, i, 0] = -1
        dest[w, tm, i, 1] = -1
        if moving[w, tm, i] and dest_ids.shape[1] > 0:
            d = _first_true(truth, w, dest_ids, j)
            if d >= 0:
                dest[w, tm, i, 0] = cell_xy[d, 0]
                dest[w, tm, i, 1] = cell_xy[d, 1]
        ammo[w, tm, i] = ammo0
        hits_made[w, tm, i] = 0
        hits_taken[w, tm, i] = 0
    for b in range(bullet_loc.shape[0]):
        tm = bullet_team[b]
        i = bullet_agent[b]
        if truth[w, bullet_flags[b, 1]]:
            ammo[w, tm, i] -= 1
        bpos[w, b, 0] = -1
        bpos[w, b, 1] = -1
        bdir[w, b] = -1
        if truth[w, bullet_flags[b, 0]]:
            c = _first_true(truth, w, bullet_loc, b)
            if c >= 0:
                bpos[w, b, 0] = cell_xy[c, 0]
                bpos[w, b, 1] = cell_xy[c, 1]
            for d in range(4):
                if truth[w, dir_ids[b, d]]:
                    bdir[w, b] = d
        for e in range(hits.shape[2]):
            for kind in range(3):
                if truth[w, hits[kind, b, e]]:
                    hits_made[w, tm, i] += 1
                    hits_taken[w, 1 - tm, e] += 1
                    kind_hits[1 - tm, e, kind] += 1
    for tm in range(2):
        win[w, tm] = truth[w, win_ids[tm]]


@njit(cache=True)
def _health(w, damage, apply_hits, kind_hits, alive, health):
    for tm in range(2):
        for i in range(alive.shape[2]):
            h = health[w, tm, i]
            if apply_hits:
                for kind in range(3):  # arrival, point blank, walk-in: one subtraction each
                    k = kind_hits[tm, i, kind]
                    if k > 0:
                        h -= damage * k
                        if h <= DEAD_EPS:
                            h = 0.0
            health[w, tm, i] = h if alive[w, tm, i] else 0.0


@njit(cache=True)
def read_and_settle(truth, agent_loc, cell_xy, agent_flags, dest_ids, bullet_loc, bullet_flags, dir_ids, hits,
                    bullet_team, bullet_agent, win_ids, ammo0, damage, kind_hits, pos, health, alive, ammo, moving,
                    dest, unsafe, invalid, acted, bpos, bdir, hits_made, hits_taken, win, was_done, weights,
                    max_steps, t, terminated, truncated, winner, agent_reward, reward):
    """After a step: read_back with the step's hits applied, then settle_step, in one call from Python
    (each call costs microseconds there, and more per array passed: docs/benchmarks.md, "Figures behind
    the code"). Returns settle_step's count of done worlds."""
    read_back(truth, agent_loc, cell_xy, agent_flags, dest_ids, bullet_loc, bullet_flags, dir_ids, hits,
              bullet_team, bullet_agent, win_ids, ammo0, damage, np.bool_(True), kind_hits, terminated, truncated, pos,
              health, alive, ammo, moving, dest, unsafe, invalid, acted, bpos, bdir, hits_made, hits_taken, win,
              was_done)
    return settle_step(was_done, win, unsafe, invalid, acted, hits_made, hits_taken, weights, max_steps, t,
                       terminated, truncated, winner, agent_reward, reward)


@njit(cache=True)
def settle_step(done, win, unsafe, invalid, acted, hits_made, hits_taken, weights, max_steps,
                t, terminated, truncated, winner, agent_reward, reward):
    """Rewards and the end of the game from the step's events (docs/game.md, Rewards / End of game).
    weights: win, loss, hit_opponent, got_shot, valid_action, unsafe, invalid. Worlds already done
    earn nothing and keep their flags; t, terminated, truncated, winner are updated in place. Returns how
    many worlds are done (terminated or truncated) afterwards."""
    r_win, r_loss, r_hit, r_shot, r_valid, r_unsafe, r_invalid = (
        weights[0], weights[1], weights[2], weights[3], weights[4], weights[5], weights[6])
    n_worlds = done.shape[0]
    n = unsafe.shape[2]
    for w in range(n_worlds):
        if done[w]:
            for tm in range(2):
                reward[w, tm] = 0.0
                for i in range(n):
                    agent_reward[w, tm, i] = 0.0
                    unsafe[w, tm, i] = False
                    invalid[w, tm, i] = False
                    hits_made[w, tm, i] = 0
                    hits_taken[w, tm, i] = 0
            continue
        t[w] += 1
        terminal0 = 0.0
        terminal1 = 0.0
        if win[w, 0] or win[w, 1]:
            terminated[w] = True
            if win[w, 0] and win[w, 1]:
                winner[w] = 2
            elif win[w, 0]:
                winner[w] = 0
                terminal0, terminal1 = r_win, r_loss
            else:
                winner[w] = 1
                terminal0, terminal1 = r_loss, r_win
        elif t[w] >= max_steps:
            truncated[w] = True
        for tm in range(2):
            terminal = terminal0 if tm == 0 else terminal1
            total = terminal  # the team's terminal term counts once
            for i in range(n):
                x = hits_made[w, tm, i] * r_hit + hits_taken[w, tm, i] * r_shot
                if unsafe[w, tm, i]:
                    x += r_unsafe
                elif invalid[w, tm, i]:
                    x += r_invalid
                elif acted[w, tm, i]:
                    x += r_valid
                total += x
                agent_reward[w, tm, i] = x + terminal
            reward[w, tm] = total
    n_done = 0
    for w in range(n_worlds):
        if terminated[w] or truncated[w]:
            n_done += 1
    return n_done
