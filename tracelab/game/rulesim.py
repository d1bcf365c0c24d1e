"""The rule-driven simulator: the game of rules/gridworld/game.rules on the logic engine.

Python here turns actions into facts, steps the engine once for all worlds, and reads the state, the
events and the end of the game back from atoms. Its API and StepResult are those of tracelab.game.refsim,
so the two simulators are interchangeable and can be compared step by step.
"""
from __future__ import annotations

import numpy as np
from tracelab.engine import Engine
from tracelab.engine.core import LANES_MIN_WORLDS

from tracelab.game import rulesim_warmup
from tracelab.game.facts import DIRECTIONS, agent_name, bullet_name, scenario_program
from tracelab.game.observe import observe_step
from tracelab.game.rulesim_fused import STATUS_BAD_ACTION, STATUS_OK, bind, fused_step
from tracelab.game.rulesim_kernel import encode_actions, read_and_settle, read_back
from tracelab.game.scenario import TEAMS, Scenario
from tracelab.game.sim_base import GameSim, read_only
from tracelab.game.state import WINNER_NONE, GameState, StepResult


class RuleSim(GameSim):
    """`n_worlds` games stepped together by one engine call per step. `trace` turns the engine's change
    log on (for all worlds, or a bool per world); take it with `self.engine.take_trace()`. `kernel`
    chooses the engine's kernel (tracelab.engine.Engine; "auto" takes the lanes kernel for 64 worlds
    or more); with `background_compile`, kernel="compiled" not yet cached is compiled in a background
    process while the engine steps on the counting kernel (Engine). `copy`: the step contract (GameSim):
    by default a StepResult's arrays are read-only views of buffers the next step or reset overwrites;
    `copy=True` returns new arrays every time.

    A step is encode_actions (actions to fact rows), the engine step, read_and_settle (atoms back into
    the state buffers, rewards, the end of the game) and observe_step (observations, in place). On the
    counting kernel they run as one compiled call (rulesim_fused.fused_step, `fused=True`; with it,
    `kernel="auto"` takes the counting kernel below the lanes kernel's batch size, not a cached compiled
    one, which measured no faster); when the kernel pauses (buffer room, user functions) or fails, the
    rest runs as separate calls. `fused=False` always takes separate calls (the same results; kept to
    compare)."""

    def __init__(self, scenario: Scenario, n_worlds: int = 1, seed: int | None = None,
                 stack_previous: bool = False, trace: bool | np.ndarray = False, kernel: str = "auto",
                 copy: bool = False, background_compile: bool = False, fused: bool = True) -> None:
        super().__init__(scenario, n_worlds, seed, stack_previous, copy)
        if fused and kernel == "auto" and n_worlds < LANES_MIN_WORLDS:
            kernel = "counting"  # what the fused step runs ("auto" would take a cached compiled kernel)
        self.engine = Engine(scenario_program(scenario), worlds=n_worlds, trace=trace, kernel=kernel,
                             background_compile=background_compile)
        self._index_atoms()
        # t = 0 sets up the start; every action atom starts false, so the rules are grounded for them
        self.engine.add_facts(self._action_atoms[self._action_atoms >= 0], 0.0, 0.0)
        self._first_step(fused)
        self._start = self.engine.snapshot()
        # the set-up rows of t = 0 (world 0's; all worlds start alike), replayed for each new episode
        self.episode_start = np.zeros(n_worlds, np.int64)  # engine time of each world's episode t = 0
        self.world_episode = np.zeros(n_worlds, np.int64)  # episodes each world has started, minus one
        self._fresh = np.ones(n_worlds, bool)  # still in the start state, its set-up rows already queued
        setup = self._take_local()
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
        r = scenario.rewards
        self._weights = np.array([r.win, r.loss, r.hit_opponent, r.got_shot, r.valid_action, r.unsafe,
                                  r.invalid], np.float64)
        self._allowed = np.zeros(9, bool)
        self._allowed[list(scenario.action_ids)] = True
        self._make_buffers()
        # every world starts alike: a reset copies these rows instead of reading atoms back
        self._start_state = {name: buf.copy() for name, buf in self._state_buffers.items()}
        self._start_obs = self._obs.copy()
        self.fused = fused
        self._bound: object | None = None  # rulesim_fused.StepBuffers of the engine's current arrays
        self._bound_version = -1  # the engine's layout_version they were bound at
        self._bound_res = np.zeros(2, np.int64)  # fused_step's report: [world the kernel paused at, rows]

    def _first_step(self, fused: bool) -> None:
        """Step t = 0. On a first run (numba's cache cold) the game's kernels compile meanwhile in a second
        process (rulesim_warmup), loaded from the cache after this step has compiled the engine's."""
        warmup = rulesim_warmup.start(self.scenario, self.n_worlds, self.stack_previous, self.engine.kernel, fused)
        try:
            self.engine.step()
        except BaseException:
            if warmup is not None:
                warmup.stop()
            raise
        if warmup is not None:
            warmup.wait()

    def _make_buffers(self) -> None:
        """The state, events, rewards and observations of every world: buffers rewritten in place by every
        step (read back from the engine's start state here), the state and result handed out as
        read-only views of them, and the compiled calls' argument lists."""
        s, w, n = self.scenario, self.n_worlds, self.scenario.agents_per_team
        n_b = len(self._bullet_team)
        shape = (w, 2, n)
        self.t = np.zeros(w, np.int32)
        self.terminated = np.zeros(w, bool)
        self.truncated = np.zeros(w, bool)
        self.winner = np.full(w, WINNER_NONE, np.int8)
        pos, dest = np.empty((*shape, 2), np.int32), np.empty((*shape, 2), np.int32)
        health = np.full(shape, float(s.health))
        alive, moving = np.empty(shape, bool), np.empty(shape, bool)
        ammo = np.empty(shape, np.int32)
        bpos, bdir = np.empty((w, n_b, 2), np.int32), np.empty((w, n_b), np.int8)
        unsafe, invalid, acted = np.zeros(shape, bool), np.zeros(shape, bool), np.zeros(shape, bool)
        hits_made, hits_taken = np.zeros(shape, np.int32), np.zeros(shape, np.int32)
        win = np.zeros((w, 2), bool)
        agent_reward, reward = np.zeros(shape), np.zeros((w, 2))
        self._was_done = np.zeros(w, bool)  # per world: finished before the last step
        # read_back's and read_and_settle's arguments after the tables, in their order
        buffers = (pos, health, alive, ammo, moving, dest, unsafe, invalid, acted, bpos, bdir, hits_made,
                   hits_taken, win, self._was_done)
        read_back(self.engine.is_true(self._read_atoms), *self._read_tables, False, self._kind_hits,
                  self.terminated, self.truncated, *buffers)
        self._settle_args = (*self._read_tables, self._kind_hits, *buffers, self._weights, s.max_steps, self.t,
                             self.terminated, self.truncated, self.winner, agent_reward, reward)
        cur = np.zeros((w, 2, self.obs_size // 2 if self.stack_previous else self.obs_size), np.float32)
        self._obs = self._with_history(cur, cur)
        self._observe_args = (pos, alive, bpos, bdir, self._state_bullet_team, bool(s.advanced),
                              self.stack_previous, self._was_done, self._obs)
        observe_step(*self._observe_args)  # no world is done yet: every observation is written
        if self.stack_previous:
            self._obs[..., self.obs_size // 2:] = self._obs[..., :self.obs_size // 2]
        self._obs_view = read_only(self._obs)
        self._policy_state = (pos, alive, ammo)
        # the state's writable buffers by GameState field: what a reset restores
        self._state_buffers = {"t": self.t, "pos": pos, "health": health, "ammo": ammo, "alive": alive,
                               "moving": moving, "dest": dest, "bullet_pos": bpos, "bullet_dir": bdir,
                               "terminated": self.terminated, "truncated": self.truncated, "winner": self.winner}
        self.state = GameState(
            t=read_only(self.t), pos=read_only(pos), health=read_only(health), ammo=read_only(ammo),
            alive=read_only(alive), moving=read_only(moving), dest=read_only(dest), bullet_pos=read_only(bpos),
            bullet_dir=read_only(bdir), terminated=read_only(self.terminated), truncated=read_only(self.truncated),
            winner=read_only(self.winner), bullet_team=self._state_bullet_team,
            bullet_agent=self._state_bullet_agent)
        st = self.state
        self._result = StepResult(
            obs=self._obs_view, positions=st.pos, health=st.health, ammo=st.ammo, alive=st.alive,
            moving=st.moving, move_dest=st.dest, bullet_pos=st.bullet_pos, bullet_dir=st.bullet_dir,
            bullet_owner=read_only(self._bullet_owner), unsafe=read_only(unsafe), invalid=read_only(invalid),
            hits_made=read_only(hits_made), hits_taken=read_only(hits_taken),
            agent_reward=read_only(agent_reward), reward=read_only(reward), terminated=st.terminated,
            truncated=st.truncated, winner=st.winner, t=st.t)

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
        self._win = ids("won", list(TEAMS))
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
                             self._bullet_team, self._bullet_agent, rows["_win"], s.ammo, float(s.damage))

    # ---- the shield ----

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
        """Start new episodes in all worlds (or those of a mask / index array); observations [W, 2, D] (a
        buffer, unless copy=True)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        # indices taken first: the mask may be a view of this simulator's own flags, reset below
        sel = np.arange(self.n_worlds) if worlds is None else (
            np.flatnonzero(worlds) if np.asarray(worlds).dtype == bool else np.array(worlds))
        sel = sel[~self._fresh[sel]]  # a world that has not stepped since its start needs nothing
        self._fresh[sel] = True
        if self.engine.trace_on.any():  # rows of the episodes that end here keep their own clock
            self._pending_rows.append(self._take_local())
        self.engine.restore(self._start, sel)  # action atoms are false again there
        self._prev_action[sel] = -1
        self.episode_start[sel] = self.engine.t - 1
        self.world_episode[sel] += 1
        if self.engine.trace_on[sel].any():
            self._replay_setup(sel[self.engine.trace_on[sel]])
        if len(sel):  # the start state, as read when the simulator was built (all worlds start alike)
            # one world (the usual episode end): basic indexing, no fancy-index copies
            where = slice(int(sel[0]), int(sel[0]) + 1) if len(sel) == 1 else sel
            self._start_state_into(where)
            self._obs[where] = self._start_obs[where]
        return self._handed_obs()

    def _start_state_into(self, sel: np.ndarray | slice) -> None:
        """Worlds `sel` of the state buffers back to the start state, in place."""
        for name, buf in self._state_buffers.items():
            buf[sel] = self._start_state[name][sel]

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
        rows = self._take_local()
        if self._pending_rows:
            self._pending_rows.append(rows)
            rows = {k: np.concatenate([r[k] for r in self._pending_rows]) for k in rows}
            self._pending_rows = []
        return rows

    def _take_local(self) -> dict[str, np.ndarray]:
        """The engine's rows with t counted from their world's current episode start, and world_episode."""
        return self.engine.take_trace(self.episode_start, self.world_episode)

    def step(self, red_actions: np.ndarray, blue_actions: np.ndarray) -> StepResult:
        """One step of every world (spec action ids, int [W, N] per team). Finished worlds do not change
        (zero rewards, flags kept) until reset."""
        if self.fused:
            return self._fused_step(red_actions, blue_actions)
        self.engine.step(external=self._action_rows(red_actions, blue_actions))
        self._fresh.fill(False)
        # finished worlds keep their final state; the clock, end flags and rewards are settled in place
        read_and_settle(self.engine.is_true(self._read_atoms), *self._settle_args)
        observe_step(*self._observe_args)
        return self._handed_out()

    def _fused_step(self, red_actions: np.ndarray, blue_actions: np.ndarray) -> StepResult:
        """step() as one compiled call (rulesim_fused.fused_step); what the kernel leaves to Python (a
        pause or an error) and the rest of the step run as the separate calls would."""
        eng = self.engine
        red = self._team_actions(red_actions, "red_actions")
        blue = self._team_actions(blue_actions, "blue_actions")
        if eng.prepare_fused_step() != self._bound_version and not self._bind():
            self.fused = False  # another kernel: separate calls from now on
            return self.step(red, blue)
        status = fused_step(self._bound, red, blue, eng.t, eng.next_external_id())
        if status == STATUS_BAD_ACTION:
            self._action_rows(red, blue)  # raises the action's error; nothing was changed
        eng.finish_fused_step(status, int(self._bound_res[0]), *self._rows_buf)
        self._fresh.fill(False)
        if status != STATUS_OK:  # the kernel paused or failed: the rest of the step as separate calls
            read_and_settle(eng.is_true(self._read_atoms), *self._settle_args)
            observe_step(*self._observe_args)
        return self._handed_out()

    def _bind(self) -> bool:
        """Bind the fused step's arrays to the engine's current ones; False on a kernel it cannot run."""
        binding = self.engine.fused_binding()
        if binding is None:
            self._bound = None
            return False
        encode = (self.terminated, self.truncated, self._allowed, self._action_atoms, self._prev_action,
                  *self._rows_buf)
        self._bound, self._bound_res = bind(encode, binding, self._read_atoms, self._settle_args,
                                            self._observe_args)
        self._bound_version = self.engine.layout_version
        return True

    def _action_rows(self, red_actions: np.ndarray,
                     blue_actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The engine's external-fact rows for both teams' actions (see encode_actions; finished worlds
        do nothing), after checking every action against what the scenario offers."""
        red = self._team_actions(red_actions, "red_actions")
        blue = self._team_actions(blue_actions, "blue_actions")
        ptr, rows, bounds = self._rows_buf
        k = encode_actions(red, blue, self.terminated, self.truncated, self._allowed, self._action_atoms,
                           self._prev_action, self.engine.next_external_id(), ptr, rows, bounds)
        if k < 0:
            w, tm, j = np.unravel_index(-1 - k, (self.n_worlds, 2, self.scenario.agents_per_team))
            raise ValueError(f"action {(red, blue)[tm][w, j]} of {TEAMS[tm]} agent {j} in world {w} is not "
                             f"offered by scenario {self.scenario.name!r} (ids {self.scenario.action_ids})")
        return ptr, rows[:k], bounds[:k]

    def _team_actions(self, actions: np.ndarray, name: str) -> np.ndarray:
        a = actions if type(actions) is np.ndarray and actions.dtype == np.int64 else np.asarray(actions, np.int64)
        if a.ndim == 1 and self.n_worlds == 1:
            a = a[None]
        shape = (self.n_worlds, self.scenario.agents_per_team)
        if a.shape != shape:
            raise ValueError(f"{name} must have shape {shape} (worlds, agents), got {a.shape}")
        flags = a.flags
        if not (flags.c_contiguous and flags.writeable):  # the compiled calls' one signature (no recompile)
            a = np.array(a, np.int64, order="C")
        return a
