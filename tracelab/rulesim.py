"""The rule-driven simulator: the game of rules/gridworld/game.rules on the logic engine.

Python here turns actions into facts, steps the engine once for all worlds, and reads the state, the
events and the end of the game back from atoms. Its API and StepResult are those of tracelab.refsim,
so the two simulators are interchangeable and can be compared step by step.
"""
from __future__ import annotations

import numpy as np

from tracelab.engine import Engine
from tracelab.game_facts import DIRECTIONS, agent_name, bullet_name, scenario_program
from tracelab.opponent import scripted_actions
from tracelab.refsim import (WINNER_BLUE, WINNER_DRAW, WINNER_NONE, WINNER_RED, GameState, StepResult,
                             obs_size, observe)
from tracelab.scenario import NOTHING, TEAMS, Scenario, team_index


class RuleSim:
    """`n_worlds` games stepped together by one engine call per step. `trace` turns the engine's change
    log on (for all worlds, or a bool per world); take it with `self.engine.take_trace()`."""

    def __init__(self, scenario: Scenario, n_worlds: int = 1, seed: int | None = None,
                 stack_previous: bool = False, trace: bool | np.ndarray = False) -> None:
        if n_worlds < 1:
            raise ValueError(f"n_worlds must be at least 1, got {n_worlds}")
        self.scenario = scenario
        self.n_worlds = n_worlds
        self.stack_previous = stack_previous
        self.rng = np.random.default_rng(seed)
        self.obs_size = obs_size(scenario, stack_previous)
        self.engine = Engine(scenario_program(scenario), worlds=n_worlds, trace=trace)
        self._index_atoms()
        # t = 0 sets up the start; every action atom starts false, so the rules are grounded for them
        self.engine.add_facts(self._action_atoms[self._action_atoms >= 0], 0.0, 0.0)
        self.engine.step()
        self._start = self.engine.snapshot()
        # the set-up rows of t = 0 (world 0's; all worlds start alike), replayed for each new episode
        self.episode_start = np.zeros(n_worlds, np.int64)  # engine time of each world's episode t = 0
        self.world_episode = np.zeros(n_worlds, np.int64)  # episodes each world has started, minus one
        self._fresh = np.ones(n_worlds, bool)  # still in the start state, its set-up rows already queued
        setup = self._localize(self.engine.take_trace())
        first = setup["world"] == 0
        self._setup_rows = {k: v[first] for k, v in setup.items()}
        self._pending_rows: list[dict[str, np.ndarray]] = [setup]
        n = scenario.agents_per_team
        self._prev_action = np.full((n_worlds, 2 * n), -1, np.int64)  # atom id of the last action set
        self.t = np.zeros(n_worlds, np.int32)
        self.terminated = np.zeros(n_worlds, bool)
        self.truncated = np.zeros(n_worlds, bool)
        self.winner = np.full(n_worlds, WINNER_NONE, np.int8)
        self._allowed = np.zeros(9, bool)
        self._allowed[list(scenario.action_ids)] = True
        self.state = self._read_state()
        self._cur = self._observe_both(self.state)
        self._obs = self._with_history(self._cur, self._cur)

    # ---- atom ids, looked up once ----

    def _index_atoms(self) -> None:
        s, eng = self.scenario, self.engine
        n, ammo = s.agents_per_team, s.ammo
        cells = [str(c) for c in range(s.width * s.height)]
        agents = [agent_name(t, j) for t in range(2) for j in range(n)]
        bullets = [bullet_name(t, j, k) for t in range(2) for j in range(n) for k in range(ammo)]
        self._cell_xy = np.array([(c % s.width, c // s.width) for c in range(s.width * s.height)], np.int32)

        def ids(pred: str, *arg_lists: list[str]) -> np.ndarray:
            grid = np.meshgrid(*[np.arange(len(a)) for a in arg_lists], indexing="ij")
            out = np.empty(grid[0].shape, np.int64)
            for idx in np.ndindex(out.shape):
                out[idx] = eng.atom(pred, *(arg_lists[k][idx[k]] for k in range(len(arg_lists))))
            return out

        self._agent_loc = ids("atLoc", agents, cells)
        self._alive = ids("alive", agents)
        self._unsafe = ids("unsafe", agents)
        self._invalid = ids("invalid", agents)
        self._can_act = ids("canAct", agents)
        self._moving = ids("moving", agents)
        self._dest = ids("dest", agents, cells) if s.slow_mask.any() else None
        self._captured = ids("captured", list(TEAMS))
        self._eliminated = ids("eliminated", list(TEAMS))
        if bullets:
            self._bullet_loc = ids("atLoc", bullets, cells)
            self._flying = ids("flying", bullets)
            self._dir = ids("dir", bullets, list(DIRECTIONS))
            self._spent = ids("spent", bullets)
            enemies = [[agent_name(1 - (b // (n * ammo)), e) for e in range(n)] for b in range(len(bullets))]
            # hits of bullet b on its owner's enemy e, by each of the three kinds of hit
            self._hits = np.stack([
                np.array([[eng.atom(kind, bullets[b], enemies[b][e]) for e in range(n)]
                          for b in range(len(bullets))], np.int64)
                for kind in ("struck", "blanked", "caught")])
        slots = np.arange(len(bullets))
        self._bullet_team = (slots // max(n * ammo, 1)).astype(np.int8)
        self._bullet_agent = ((slots // max(ammo, 1)) % n).astype(np.int16)
        # action atom per (agent, spec action id); -1 for "do nothing"
        acts = np.full((2 * n, 9), -1, np.int64)
        for i, a in enumerate(agents):
            for d, name in enumerate(DIRECTIONS):
                acts[i, d] = eng.atom("move", a, name)
                if s.advanced:
                    acts[i, 4 + d] = eng.atom("shoot", a, name)
        self._action_atoms = acts

    # ---- reading the world back ----

    def _true(self, ids: np.ndarray) -> np.ndarray:
        return self.engine.lower[:, ids] >= 1.0

    def _read_state(self) -> GameState:
        s = self.scenario
        w, n, ammo = self.n_worlds, s.agents_per_team, s.ammo
        at = self._true(self._agent_loc)  # [W, 2N, C]
        pos = self._cell_xy[np.argmax(at, axis=2)].reshape(w, 2, n, 2)
        alive = self._true(self._alive).reshape(w, 2, n)
        n_b = 2 * n * ammo
        if n_b:
            flying = self._true(self._flying)
            bcell = np.argmax(self._true(self._bullet_loc), axis=2)
            bpos = np.where(flying[..., None], self._cell_xy[bcell], -1).astype(np.int32)
            bdir = np.where(flying, np.argmax(self._true(self._dir), axis=2), -1).astype(np.int8)
            spent = self._true(self._spent).reshape(w, 2, n, ammo).sum(axis=3)
        else:
            bpos = np.zeros((w, 0, 2), np.int32)
            bdir = np.zeros((w, 0), np.int8)
            spent = np.zeros((w, 2, n), np.int64)
        moving = self._true(self._moving).reshape(w, 2, n)
        dest = np.full((w, 2, n, 2), -1, np.int32)
        if self._dest is not None:  # where a slow agent that set off this step will arrive
            going = self._true(self._dest)
            cell_xy = self._cell_xy[np.argmax(going, axis=2)].reshape(w, 2, n, 2)
            dest = np.where(moving[..., None], cell_xy, -1).astype(np.int32)
        return GameState(
            t=self.t.copy(), pos=pos.astype(np.int32),
            health=np.where(alive, s.health, 0.0), ammo=(ammo - spent).astype(np.int32), alive=alive,
            moving=moving, dest=dest, bullet_pos=bpos, bullet_dir=bdir,
            terminated=self.terminated.copy(), truncated=self.truncated.copy(), winner=self.winner.copy(),
            bullet_team=self._bullet_team, bullet_agent=self._bullet_agent)

    def _observe_both(self, state: GameState) -> np.ndarray:
        return np.stack([observe(state, t, self.scenario) for t in (0, 1)], axis=1)

    def _with_history(self, cur: np.ndarray, prev: np.ndarray) -> np.ndarray:
        return np.concatenate([cur, prev], axis=2) if self.stack_previous else cur

    # ---- the RefSim API ----

    def observe(self, team: int | str) -> np.ndarray:
        return self._obs[:, team_index(team)].copy()

    def reset(self, seed: int | None = None, worlds: np.ndarray | None = None) -> np.ndarray:
        """Start new episodes in all worlds (or those of a mask / index array); observations [W, 2, D]."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        sel = np.arange(self.n_worlds) if worlds is None else (
            np.flatnonzero(worlds) if np.asarray(worlds).dtype == bool else np.asarray(worlds))
        sel = sel[~self._fresh[sel]]  # a world that has not stepped since its start needs nothing
        self._fresh[sel] = True
        if self.engine.trace_on.any():  # rows of the episodes that end here keep their own clock
            self._pending_rows.append(self._localize(self.engine.take_trace()))
        self.engine.restore(self._start, sel)  # action atoms are false again there
        self._prev_action[sel] = -1
        self.episode_start[sel] = self.engine.t - 1
        self.world_episode[sel] += 1
        if self.engine.trace_on[sel].any():
            self._replay_setup(sel[self.engine.trace_on[sel]])
        self.t[sel] = 0
        self.terminated[sel] = False
        self.truncated[sel] = False
        self.winner[sel] = WINNER_NONE
        self.state = self._read_state()
        cur = self._observe_both(self.state)
        obs = self._obs.copy()
        obs[sel] = self._with_history(cur, cur)[sel]
        self._cur[sel] = cur[sel]
        self._obs = obs
        return obs.copy()

    def _replay_setup(self, worlds: np.ndarray) -> None:
        """A restored world starts from the set-up state without re-deriving it; its t = 0 rows are
        written again (at the episode's own t = 0) so each episode's trace explains itself."""
        n = len(self._setup_rows["t"])
        rows = {k: np.tile(v, len(worlds)) for k, v in self._setup_rows.items()}
        rows["world"] = np.repeat(worlds, n).astype(np.int32)
        rows["world_episode"] = np.repeat(self.world_episode[worlds], n)
        self._pending_rows.append(rows)

    def take_trace(self) -> dict[str, np.ndarray]:
        """The engine's change rows since the last call, with `t` counted from each world's episode start
        (0 = set-up) and `world_episode`, the number of that world's episode (0 = its first)."""
        self._pending_rows.append(self._localize(self.engine.take_trace()))
        rows = {k: np.concatenate([r[k] for r in self._pending_rows]) for k in self._pending_rows[0]}
        self._pending_rows = []
        return rows

    def _localize(self, rows: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Engine rows with t counted from their world's current episode start, and world_episode."""
        world = rows["world"].astype(np.int64)
        rows["t"] = (rows["t"] - self.episode_start[world]).astype(np.int32)
        rows["world_episode"] = self.world_episode[world].copy()
        return rows

    def _set_actions(self, acts: np.ndarray) -> None:
        """Action facts for the next step: the chosen action true, the previous one false (if changed)."""
        n_worlds, n_agents = self._prev_action.shape
        new = self._action_atoms[np.arange(n_agents)[None, :], acts.reshape(n_worlds, n_agents)]
        prev = self._prev_action
        changed = new != prev
        worlds = np.broadcast_to(np.arange(n_worlds)[:, None], new.shape)
        off = changed & (prev >= 0)
        on = changed & (new >= 0)
        atoms = np.concatenate([prev[off], new[on]])
        bounds = np.concatenate([np.zeros(int(off.sum())), np.ones(int(on.sum()))])
        if atoms.size:
            self.engine.add_facts(atoms, bounds, bounds, np.concatenate([worlds[off], worlds[on]]))
        self._prev_action = new

    def step(self, red_actions: np.ndarray, blue_actions: np.ndarray) -> StepResult:
        """One step of every world (spec action ids, int [W, N] per team). Finished worlds do not change
        (zero rewards, flags kept) until reset."""
        s = self.scenario
        n_worlds, n = self.n_worlds, s.agents_per_team
        acts = np.stack([self._check(red_actions, "red_actions"), self._check(blue_actions, "blue_actions")],
                        axis=1)
        done = self.terminated | self.truncated
        acts[done] = NOTHING
        self._fresh[:] = False
        before = self.state
        self._set_actions(acts)
        self.engine.step()
        state = self._read_state()
        # events of this step, per agent [W, 2, N]
        unsafe = self._true(self._unsafe).reshape(n_worlds, 2, n)
        invalid = self._true(self._invalid).reshape(n_worlds, 2, n)
        acted = self._true(self._can_act).reshape(n_worlds, 2, n)
        hits_taken = np.zeros((n_worlds, 2, n), np.int32)
        hits_made = np.zeros((n_worlds, 2, n), np.int32)
        if s.ammo:
            hit = self._true(self._hits).sum(axis=1)  # [W, B, N enemies]
            per_bullet = hit.sum(axis=2)
            for b in range(per_bullet.shape[1]):  # credited to the bullet's owner
                hits_made[:, self._bullet_team[b], self._bullet_agent[b]] += per_bullet[:, b]
            for team in (0, 1):
                from_enemy = self._bullet_team == 1 - team
                hits_taken[:, team] = hit[:, from_enemy].sum(axis=1)
        r = s.rewards
        agent_reward = (np.where(acted & ~unsafe & ~invalid, r.valid_action, 0.0) + unsafe * r.unsafe
                        + invalid * r.invalid + hits_made * r.hit_opponent + hits_taken * r.got_shot)
        win = np.stack([self._true(self._captured) | self._true(self._eliminated)[:, ::-1]], axis=0)[0]
        live = ~done
        self.t[live] += 1
        ended = live & win.any(axis=1)
        self.terminated |= ended
        self.winner[ended] = np.where(win[ended].all(axis=1), WINNER_DRAW,
                                      np.where(win[ended, 0], WINNER_RED, WINNER_BLUE))
        self.truncated |= live & ~ended & (self.t >= s.max_steps)
        decided = ended & ~win.all(axis=1)
        terminal = np.zeros((n_worlds, 2))
        red_won = self.winner == WINNER_RED
        terminal[decided] = np.where(red_won[decided, None], [r.win, r.loss], [r.loss, r.win])
        agent_reward = agent_reward + terminal[:, :, None]
        reward = agent_reward.sum(axis=2) - terminal * (n - 1)  # the terminal term counts once per team
        # finished worlds keep their final state and earn nothing
        agent_reward[done] = 0.0
        reward[done] = 0.0
        for f in ("pos", "health", "ammo", "alive", "moving", "dest", "bullet_pos", "bullet_dir"):
            getattr(state, f)[done] = getattr(before, f)[done]
        for arr in (unsafe, invalid):
            arr[done] = False
        hits_made[done] = 0
        hits_taken[done] = 0
        state.t, state.terminated, state.truncated = self.t.copy(), self.terminated.copy(), self.truncated.copy()
        state.winner = self.winner.copy()
        self.state = state
        cur = self._observe_both(state)
        cur[done] = self._cur[done]
        obs = self._with_history(cur, self._cur)
        obs[done] = self._obs[done]
        self._cur, self._obs = cur, obs
        return StepResult(
            obs=obs, positions=state.pos.copy(), health=state.health.copy(), ammo=state.ammo.copy(),
            alive=state.alive.copy(), moving=state.moving.copy(), move_dest=state.dest.copy(), bullet_pos=state.bullet_pos.copy(),
            bullet_dir=state.bullet_dir.copy(),
            bullet_owner=np.stack([self._bullet_team, self._bullet_agent], axis=1).astype(np.int64),
            unsafe=unsafe, invalid=invalid, hits_made=hits_made, hits_taken=hits_taken,
            agent_reward=agent_reward, reward=reward, terminated=self.terminated.copy(),
            truncated=self.truncated.copy(), winner=self.winner.copy(), t=self.t.copy())

    def _check(self, actions: np.ndarray, name: str) -> np.ndarray:
        a = np.asarray(actions, np.int64)
        if a.ndim == 1 and self.n_worlds == 1:
            a = a[None]
        shape = (self.n_worlds, self.scenario.agents_per_team)
        if a.shape != shape:
            raise ValueError(f"{name} must have shape {shape} (worlds, agents), got {a.shape}")
        bad = (a < 0) | (a > 8) | ~self._allowed[np.clip(a, 0, 8)]
        if bad.any():
            w, j = np.argwhere(bad)[0]
            raise ValueError(f"action {a[w, j]} of {name[:-8]} agent {j} in world {w} is not offered by "
                             f"scenario {self.scenario.name!r} (ids {self.scenario.action_ids})")
        return a.copy()

    def scripted_actions(self, team: int | str = "blue") -> np.ndarray:
        s = self.state
        return scripted_actions(s.pos, s.alive, s.ammo, team, self.scenario, self.rng)
