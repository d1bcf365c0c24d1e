"""The rule-driven simulator: the game of rules/gridworld/game.rules on the logic engine.

Python here turns actions into facts, steps the engine once for all worlds, and reads the state, the
events and the end of the game back from atoms. Its API and StepResult are those of tracelab.game.refsim,
so the two simulators are interchangeable and can be compared step by step.
"""
from __future__ import annotations

from dataclasses import fields

import numpy as np
from tracelab.engine import Engine

from tracelab.game.facts import DIRECTIONS, agent_name, bullet_name, scenario_program
from tracelab.game.rulesim_kernel import encode_actions, read_and_settle, read_back
from tracelab.game.scenario import TEAMS, Scenario
from tracelab.game.sim_base import GameSim
from tracelab.game.state import WINNER_NONE, GameState, StepResult


class RuleSim(GameSim):
    """`n_worlds` games stepped together by one engine call per step. `trace` turns the engine's change
    log on (for all worlds, or a bool per world); take it with `self.engine.take_trace()`. `kernel`
    chooses the engine's kernel (tracelab.engine.Engine; "auto" takes the lanes kernel for 64 worlds
    or more)."""

    def __init__(self, scenario: Scenario, n_worlds: int = 1, seed: int | None = None,
                 stack_previous: bool = False, trace: bool | np.ndarray = False, kernel: str = "auto") -> None:
        super().__init__(scenario, n_worlds, seed, stack_previous)
        self.engine = Engine(scenario_program(scenario), worlds=n_worlds, trace=trace, kernel=kernel)
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
        for v in self._setup_rows.values():
            v.flags.writeable = False  # replayed at every reset, shared by the queued rows
        self._pending_rows: list[dict[str, np.ndarray]] = [setup]
        n = scenario.agents_per_team
        self._prev_action = np.full((n_worlds, 2 * n), -1, np.int64)  # atom id of the last action set
        cap = 2 * n_worlds * 2 * n  # at most two rows (old action off, new on) per agent
        # the action rows' buffers, reused every step (the engine reads them within step())
        self._rows_buf = (np.empty(n_worlds + 1, np.int64), np.empty((cap, 3), np.int64),
                          np.empty((cap, 2), np.float64))
        self.t = np.zeros(n_worlds, np.int32)
        self.terminated = np.zeros(n_worlds, bool)
        self.truncated = np.zeros(n_worlds, bool)
        self.winner = np.full(n_worlds, WINNER_NONE, np.int8)
        r = scenario.rewards
        self._weights = np.array([r.win, r.loss, r.hit_opponent, r.got_shot, r.valid_action, r.unsafe,
                                  r.invalid], np.float64)
        self._allowed = np.zeros(9, bool)
        self._allowed[list(scenario.action_ids)] = True
        self._no_world_done = np.zeros(n_worlds, bool)  # read-only stand-in for "no world is done"
        self._no_world_done.flags.writeable = False
        self._n_done = 0  # worlds terminated or truncated and not yet reset
        self.state = self._read_state()
        self._cur = self._observe_both(self.state)
        self._obs = self._with_history(self._cur, self._cur)
        # every world starts alike: a reset copies these rows instead of reading atoms back
        self._start_state, self._start_cur = self.state, self._cur.copy()
        for a in (*(getattr(self.state, f.name) for f in fields(self.state)), self._start_cur):
            a.flags.writeable = False  # self.state is the caller's to read until the first step

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
        # per agent: alive, moving, unsafe, invalid, canAct (read_back's agent_flags layout)
        self._agent_flags = np.stack([ids(p, agents) for p in ("alive", "moving", "unsafe", "invalid",
                                                               "canAct")], axis=1)
        self._dest = ids("dest", agents, cells) if s.slow_mask.any() else np.zeros((2 * n, 0), np.int64)
        self._win = np.stack([ids("captured", list(TEAMS)), ids("eliminated", list(TEAMS))], axis=1)
        # the shield's view of the next step (game.rules, section 7)
        self._blocked_move = ids("blockedMove", agents, list(DIRECTIONS))
        self._no_ammo = ids("noAmmo", agents)
        self._may_act = ids("mayAct", agents)
        n_b = len(bullets)
        if bullets:
            self._bullet_loc = ids("atLoc", bullets, cells)
            self._bullet_flags = np.stack([ids("flying", bullets), ids("spent", bullets)], axis=1)
            self._dir = ids("dir", bullets, list(DIRECTIONS))
            enemies = [[agent_name(1 - (b // (n * ammo)), e) for e in range(n)] for b in range(n_b)]
            # hits of bullet b on its owner's enemy e, by each of the three kinds of hit
            self._hits = np.stack([
                np.array([[eng.atom(kind, bullets[b], enemies[b][e]) for e in range(n)]
                          for b in range(n_b)], np.int64)
                for kind in ("struck", "blanked", "caught")])
        else:
            self._bullet_loc = np.zeros((0, len(cells)), np.int64)
            self._bullet_flags = np.zeros((0, 2), np.int64)
            self._dir = np.zeros((0, 4), np.int64)
            self._hits = np.zeros((3, 0, n), np.int64)
        slots = np.arange(n_b)
        self._bullet_team = (slots // max(n * ammo, 1)).astype(np.int64)
        self._bullet_agent = ((slots // max(ammo, 1)) % n).astype(np.int64)
        self._bullet_owner = np.stack([self._bullet_team, self._bullet_agent], axis=1)
        self._state_bullet_team = self._bullet_team.astype(np.int8)  # GameState's dtypes (constant)
        self._state_bullet_agent = self._bullet_agent.astype(np.int16)
        # action atom per (agent, spec action id); -1 for "do nothing"
        acts = np.full((2 * n, 9), -1, np.int64)
        for i, a in enumerate(agents):
            for d, name in enumerate(DIRECTIONS):
                acts[i, d] = eng.atom("move", a, name)
                if s.advanced:
                    acts[i, 4 + d] = eng.atom("shoot", a, name)
        self._action_atoms = acts
        self._kind_hits = np.zeros((2, n, 3), np.int64)  # read_back's scratch
        # read-back: the atoms read after every step, once per step as a truth table (Engine.is_true); the
        # id arrays above become column numbers of that table
        tables = ("_agent_loc", "_agent_flags", "_dest", "_bullet_loc", "_bullet_flags", "_dir", "_hits", "_win")
        self._read_atoms = np.unique(np.concatenate([getattr(self, name).ravel() for name in tables]))
        rows = {name: np.searchsorted(self._read_atoms, getattr(self, name)).astype(np.int64) for name in tables}
        self._shield_true = np.concatenate([self._may_act, self._no_ammo])  # allowed_actions reads them
        # read_back's arguments that never change, agent_loc to damage: one tuple, not a lookup each step
        self._read_tables = (rows["_agent_loc"], self._cell_xy, rows["_agent_flags"], rows["_dest"],
                             rows["_bullet_loc"], rows["_bullet_flags"], rows["_dir"], rows["_hits"],
                             self._bullet_team, self._bullet_agent, rows["_win"], s.ammo, float(s.health),
                             float(s.damage))

    # ---- reading the world back ----

    def _read_state(self, done: np.ndarray | None = None, settle: bool = False) -> GameState:
        """The game state of every world, read from atoms (and the events of the last step into
        self._events: unsafe, invalid, acted [W, 2, N]; hits made / taken; which team won). Worlds in
        `done` keep their state from self.state and have no events. With `settle` (after a step) the
        step's rewards and the end of the game are settled first (settle_step; rewards into
        self._rewards), and health takes the step's hits from self.state's; else health is the scenario's
        (the start state). t, terminated, truncated and winner are copies of the simulator's
        after that."""
        s = self.scenario
        w, n = self.n_worlds, s.agents_per_team
        n_b = len(self._bullet_team)
        pos = np.empty((w, 2, n, 2), np.int32)
        health = np.empty((w, 2, n), np.float64)
        alive = np.empty((w, 2, n), bool)
        ammo = np.empty((w, 2, n), np.int32)
        moving = np.empty((w, 2, n), bool)
        dest = np.empty((w, 2, n, 2), np.int32)
        unsafe = np.empty((w, 2, n), bool)
        invalid = np.empty((w, 2, n), bool)
        acted = np.empty((w, 2, n), bool)
        bpos = np.empty((w, n_b, 2), np.int32)
        bdir = np.empty((w, n_b), np.int8)
        hits_made = np.empty((w, 2, n), np.int32)
        hits_taken = np.empty((w, 2, n), np.int32)
        win = np.empty((w, 2), bool)
        if done is None:  # no world keeps its state: the new arrays stand in for the unread prev_* ones
            done, prev = self._no_world_done, (pos, alive, ammo, moving, dest, bpos, bdir)
        else:
            st = self.state
            prev = (st.pos, st.alive, st.ammo, st.moving, st.dest, st.bullet_pos, st.bullet_dir)
        truth = self.engine.is_true(self._read_atoms)
        out = (pos, health, alive, ammo, moving, dest, unsafe, invalid, acted, bpos, bdir, hits_made, hits_taken,
               win)
        if settle:
            agent_reward = np.empty((w, 2, n))
            reward = np.empty((w, 2))
            self._n_done = read_and_settle(truth, *self._read_tables, self.state.health, self._kind_hits, done,
                                           *prev, *out, self._weights, s.max_steps, self.t, self.terminated,
                                           self.truncated, self.winner, agent_reward, reward)
            self._rewards = (agent_reward, reward)
        else:
            read_back(truth, *self._read_tables, False, np.full((w, 2, n), float(s.health)), self._kind_hits,
                      done, *prev, *out)
        self._events = (unsafe, invalid, acted, hits_made, hits_taken, win)
        return GameState(
            t=self.t.copy(), pos=pos, health=health, ammo=ammo, alive=alive, moving=moving, dest=dest,
            bullet_pos=bpos, bullet_dir=bdir, terminated=self.terminated.copy(),
            truncated=self.truncated.copy(), winner=self.winner.copy(),
            bullet_team=self._state_bullet_team, bullet_agent=self._state_bullet_agent)

    def allowed_actions(self) -> np.ndarray:
        """Which spec actions (ids 0..8) each agent may take next step, as the shield rules see it after
        this step (game.rules section 7): bool [W, 2, N, 9]. Moves must not be blocked (off the map,
        into a mountain), shots need ammo, only an agent that may act has a choice; nothing is always
        allowed. Actions the scenario does not offer are False."""
        w, n = self.n_worlds, self.scenario.agents_per_team
        true = self.engine.is_true(self._shield_true)  # worlds x [may_act..., no_ammo...]
        may = true[:, :2 * n].reshape(w, 2, n)
        out = np.zeros((w, 2, n, 9), bool)
        free = self.engine.is_false(self._blocked_move.ravel()).reshape(w, 2, n, 4)
        out[..., :4] = free & may[..., None]
        if self.scenario.advanced:
            out[..., 4:8] = (may & ~true[:, 2 * n:].reshape(w, 2, n))[..., None]
        out[..., 8] = True
        return out

    # ---- the RefSim API ----

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
        self._n_done = int((self.terminated | self.truncated).sum())
        self.winner[sel] = WINNER_NONE
        self.state = self._restarted_state(sel)
        # new arrays: the caller may hold the last step's observation (the same array)
        cur = self._cur.copy()
        cur[sel] = self._start_cur[sel]
        obs = self._obs.copy()
        obs[sel] = self._with_history(cur[sel], cur[sel])
        self._cur, self._obs = cur, obs
        return obs.copy()

    def _restarted_state(self, sel: np.ndarray) -> GameState:
        """self.state with worlds `sel` back in the start state (as read when the simulator was built)."""
        st, start = self.state, self._start_state
        # every world in the start state (e.g. the one world of an env): the start rows as they are (read-only)
        every = bool(self._fresh.all())
        rows = {}
        for name in ("pos", "health", "ammo", "alive", "moving", "dest", "bullet_pos", "bullet_dir"):
            if every:
                rows[name] = getattr(start, name)
                continue
            a = getattr(st, name).copy()
            a[sel] = getattr(start, name)[sel]
            rows[name] = a
        return GameState(t=self.t.copy(), terminated=self.terminated.copy(), truncated=self.truncated.copy(),
                         winner=self.winner.copy(), bullet_team=self._state_bullet_team,
                         bullet_agent=self._state_bullet_agent, **rows)

    def _replay_setup(self, worlds: np.ndarray) -> None:
        """A restored world starts from the set-up state without re-deriving it; its t = 0 rows are
        written again (at the episode's own t = 0) so each episode's trace explains itself."""
        n, k = len(self._setup_rows["t"]), len(worlds)
        # one world: the (read-only) set-up columns as they are; take_trace() concatenates them anyway
        rows = {c: v if k == 1 else np.broadcast_to(v, (k, n)).ravel() for c, v in self._setup_rows.items()}
        rows["world"] = np.repeat(worlds, n).astype(np.int32)
        rows["world_episode"] = np.repeat(self.world_episode[worlds], n)
        self._pending_rows.append(rows)

    def take_trace(self) -> dict[str, np.ndarray]:
        """The engine's change rows since the last call, with `t` counted from each world's episode start
        (0 = set-up) and `world_episode`, the number of that world's episode (0 = its first)."""
        rows = self._localize(self.engine.take_trace())
        if self._pending_rows:
            self._pending_rows.append(rows)
            rows = {k: np.concatenate([r[k] for r in self._pending_rows]) for k in rows}
            self._pending_rows = []
        return rows

    def _localize(self, rows: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Engine rows with t counted from their world's current episode start, and world_episode."""
        if self.n_worlds == 1:  # the common single-world case, without per-row gathers
            start = int(self.episode_start[0])
            if start:
                rows["t"] -= start
            episode = np.empty(len(rows["t"]), np.int64)
            episode.fill(int(self.world_episode[0]))
            rows["world_episode"] = episode
            return rows
        world = rows["world"].astype(np.int64)
        rows["t"] = (rows["t"] - self.episode_start[world]).astype(np.int32)
        rows["world_episode"] = self.world_episode[world].copy()
        return rows

    def step(self, red_actions: np.ndarray, blue_actions: np.ndarray) -> StepResult:
        """One step of every world (spec action ids, int [W, N] per team). Finished worlds do not change
        (zero rewards, flags kept) until reset."""
        any_done = self._n_done > 0
        done = self.terminated | self.truncated if any_done else self._no_world_done
        self.engine.step(external=self._action_rows(red_actions, blue_actions, done))
        self._fresh[:] = False
        # finished worlds keep their final state; the clock and end flags are read after settling
        state = self._read_state(done if any_done else None, settle=True)
        unsafe, invalid, acted, hits_made, hits_taken, _ = self._events
        agent_reward, reward = self._rewards
        for a in (state.pos, state.health, state.ammo, state.alive, state.moving, state.dest, state.bullet_pos,
                  state.bullet_dir, state.t, state.terminated, state.truncated, state.winner):
            a.setflags(write=False)  # shared by the state and the result: nobody may change them
        self.state = state
        cur = self._observe_both(state)
        obs = self._with_history(cur, self._cur)
        if any_done:
            cur[done] = self._cur[done]
            obs[done] = self._obs[done]
        self._cur, self._obs = cur, obs
        return StepResult(
            obs=obs, positions=state.pos, health=state.health, ammo=state.ammo, alive=state.alive,
            moving=state.moving, move_dest=state.dest, bullet_pos=state.bullet_pos,
            bullet_dir=state.bullet_dir, bullet_owner=self._bullet_owner,
            unsafe=unsafe, invalid=invalid, hits_made=hits_made, hits_taken=hits_taken,
            agent_reward=agent_reward, reward=reward, terminated=state.terminated,
            truncated=state.truncated, winner=state.winner, t=state.t)

    def _action_rows(self, red_actions: np.ndarray, blue_actions: np.ndarray,
                     done: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The engine's external-fact rows for both teams' actions (see encode_actions; done worlds do
        nothing), after checking every action against what the scenario offers."""
        red = self._team_actions(red_actions, "red_actions")
        blue = self._team_actions(blue_actions, "blue_actions")
        ptr, rows, bounds = self._rows_buf
        k = encode_actions(red, blue, done, self._allowed, self._action_atoms, self._prev_action,
                           self.engine.next_external_id(), ptr, rows, bounds)
        if k < 0:
            w, tm, j = np.unravel_index(-1 - k, (self.n_worlds, 2, self.scenario.agents_per_team))
            raise ValueError(f"action {(red, blue)[tm][w, j]} of {TEAMS[tm]} agent {j} in world {w} is not "
                             f"offered by scenario {self.scenario.name!r} (ids {self.scenario.action_ids})")
        return ptr, rows[:k], bounds[:k]

    def _team_actions(self, actions: np.ndarray, name: str) -> np.ndarray:
        a = np.asarray(actions, np.int64)
        if a.ndim == 1 and self.n_worlds == 1:
            a = a[None]
        shape = (self.n_worlds, self.scenario.agents_per_team)
        if a.shape != shape:
            raise ValueError(f"{name} must have shape {shape} (worlds, agents), got {a.shape}")
        return a
