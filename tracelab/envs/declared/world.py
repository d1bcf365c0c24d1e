"""A declared world running: the spec's program on the engine, facts in and atoms out, one world.

Timeline (docs/worlds.md, "How a step runs"):
- built: the engine's t = 0 applies the program's and the board's facts; every atom the env will set
  (actions, random facts, start facts and choices) is set to [0,0] there, so that the rules are grounded
  for them; the state after it is the snapshot every episode starts from.
- reset: the snapshot is restored, the start choices are drawn from np_random (in the spec's order) and
  one engine step applies the start facts and the chosen atoms ([1,1], or the fact's bound).
- step: the action's facts and one value of each random fact (drawn in the spec's order) are set for the
  step; last step's facts that are not set again go back to [0,0]. One engine step; the reward is read.
  Then each `after` random fact whose atom is true is drawn, and if any was, one more engine step applies
  them (the step's facts back to [0,0]) and its reward is added. The observation and ends are read last.
Draws follow gymnasium: "categorical" is `categorical_sample` (one `np_random.random()` u, the first
value whose cumulative probability exceeds u), "choice" is `np_random.choice` over the possible values
(one `integers(0, n)`), so a seeded world draws exactly as gymnasium's toy-text games do."""
from __future__ import annotations

from typing import Any

import numpy as np

from tracelab.engine import Engine
from tracelab.engine import kernel as counting_kernel
from tracelab.engine import lanes as lanes_kernel
from tracelab.engine.numba_cache import is_cached
from tracelab.envs.declared import fused, vector_fused
from tracelab.envs.declared.computed import ComputedFacts
from tracelab.envs.declared.observe_kernel import ObservationProgram, ObservationReader, split_parts
from tracelab.envs.declared.spec import Atom, Draw, WorldSpec
from tracelab.envs.declared.state_errors import no_index, no_weights_hold
from tracelab.board import DIRECTION_ARROWS
from tracelab.first_run_figures import say_first_compile
from tracelab.engine.notices import library_logger

log = library_logger(__name__)


def categorical(cumulative: list[float], rng: np.random.Generator) -> int:
    """gymnasium.envs.toy_text.utils.categorical_sample, draw for draw: one rng.random() u, and the first
    value whose cumulative probability (np.cumsum of the probabilities, the same float64 sums) exceeds u,
    or value 0 when none does (argmax of all-false)."""
    u = rng.random()
    for i, c in enumerate(cumulative):
        if c > u:
            return i
    return 0


class _Drawer:
    """One Draw's engine ids and how it picks a value."""

    def __init__(self, draw: Draw, ids: Any) -> None:
        self.draw = draw
        self.value_ids = [ids(atoms) for atoms in draw.atoms]
        self.value_bounds = [_bounds(atoms) for atoms in draw.atoms]
        self.cumulative = None if draw.probabilities is None else np.cumsum(draw.probabilities).tolist()
        self.weight_ids = None if draw.weights is None else \
            np.array([ids(w) for w in draw.weights], np.int64).reshape(len(draw.weights), -1)
        self.after = None if draw.after is None else ids([draw.after])
        self.possible: np.ndarray | None = None
        self.frozen = False

    def pick(self, world: DeclaredWorld, rng: np.random.Generator) -> int:
        d = self.draw
        if self.weight_ids is None and self.possible is None:
            if d.method == "choice":
                return int(rng.integers(0, len(self.value_ids)))
            return categorical(self.cumulative, rng)  # type: ignore[arg-type]
        possible, cumulative = (self.possible, self.cumulative) if self.frozen else self._weighed(world)
        if d.method == "choice":
            return int(possible[rng.integers(0, possible.size)])
        return categorical(cumulative, rng)

    def freeze(self, world: DeclaredWorld) -> None:
        """Read the weights now, once: a start choice reads them on the snapshot every episode starts
        from, so they never change."""
        if self.weight_ids is not None:
            self.possible, self.cumulative = self._weighed(world)
            self.frozen = True

    def _weighed(self, world: DeclaredWorld) -> tuple[np.ndarray, list[float]]:
        """The values whose weights all hold, and the cumulative probabilities of choosing each value."""
        d, w = self.draw, self.weight_ids
        ok = world.engine.is_true(w.ravel())[0].reshape(w.shape).all(axis=1)
        possible = np.flatnonzero(ok)
        if possible.size == 0:
            raise no_weights_hold(world.spec, d)
        p = ok.astype(np.float64)
        p /= p.sum()  # as gymnasium normalises initial_state_distrib
        return possible, np.cumsum(p).tolist()


def _say_if_cold(spec: WorldSpec, kernel: str, worlds: int) -> None:
    """Before the build: one notice (once per process) when the kernels this world steps on are not in
    numba's cache yet, so their first call compiles them (the notice quotes what bench first-run measured)."""
    if kernel == "counting":
        engine = counting_kernel.step_worlds
        world = (fused.fused_step, fused.read_step) if worlds == 1 else (vector_fused.step_worlds, vector_fused.read_batch)
    elif kernel == "lanes":
        engine, world = lanes_kernel.step_lanes, (vector_fused.prepare_batch, vector_fused.read_truth)
    else:
        return  # the compiled backend says its own (tracelab compile)
    phase = "spec-env" if worlds == 1 else "spec-vector-env"
    what = "the rule engine's step kernel and a declared world's " + ("step" if worlds == 1 else "batch step")
    say_first_compile(log, phase, f"{what} for {spec.path}", (is_cached(k) for k in (engine, *world)))


class DeclaredWorld:
    """One world of `spec` on its own engine (`kernel`: the engine's; `trace`: its change log)."""

    def __init__(self, spec: WorldSpec, *, kernel: str = "auto", trace: bool = False, worlds: int = 1) -> None:
        self.spec = spec
        # one world steps fastest on the counting kernel inside one compiled call (fused.py); another
        # kernel asked for by name runs its own steps. `worlds` > 1: the engine of a batch, which
        # vector_world.DeclaredWorlds steps (this object's reset and step serve one world only)
        _say_if_cold(spec, "counting" if kernel == "auto" else kernel, worlds)  # the engine's build steps it once
        # an env never waits for a compile: "compiled" not yet cached is built in a child meanwhile
        self.engine = eng = Engine(spec.program, worlds=worlds, trace=trace,
                                   kernel="counting" if kernel == "auto" else kernel, background_compile=True,
                                   cache_grounding=True)
        ids = self._ids
        # the facts of each (agent, action) row: row agent * n_actions + action
        self.n_agents, self.n_actions = len(spec.agents), len(spec.action_names)
        self._action_ids = [ids(facts) for per_agent in spec.action_facts for facts in per_agent]
        self._action_bounds = [_bounds(facts) for per_agent in spec.action_facts for facts in per_agent]
        self._rows = np.full(self.n_agents, -1, np.int64)  # this step's rows, one per agent
        self._choices = [_Drawer(d, ids) for d in spec.start_choices]
        self._before = [_Drawer(d, ids) for d in spec.random_facts if d.after is None]
        self._after = [_Drawer(d, ids) for d in spec.random_facts if d.after is not None]
        self._start_ids, self._start_bounds = ids(spec.start_facts), _bounds(spec.start_facts)
        self._computed = ComputedFacts(spec, ids)  # the clocks' and nearest facts, set for each step
        self._win_ids, self._loss_ids = ids(spec.win), ids(spec.loss)
        self._decides_ids, self._alive_ids = ids(spec.decides), ids(spec.alive)  # [agents] decides, alive
        # [agents] script: [agent * action]
        self._script_ids = np.concatenate([ids(m) for m in spec.script]) if spec.script else np.zeros(0, np.int64)
        env_set = [self._start_ids, *self._action_ids]
        for drawer in (*self._choices, *self._before, *self._after):
            env_set.extend(drawer.value_ids)
        for values in self._computed.value_ids:
            env_set.extend(values)
        env_set_ids = np.unique(np.concatenate([np.zeros(0, np.int64), *env_set]))
        if env_set_ids.size:
            eng.add_facts(env_set_ids, 0.0, 0.0)
        # what is read after each step: index parts, the reward table, the ends and the mask in one
        # compiled call (fused.read_step); the other parts and scaled rewards from the bound arrays
        self._index_parts = [i for i, p in enumerate(spec.parts) if p.read == "index"]
        # an index part with no `missing` makes a -1 an error; with none such (the war game's: a dead agent is
        # seen nowhere), observations skip the per-part check (20v20: 80 parts an agent, in Python at each read)
        self._index_checked = any(spec.parts[i].missing is None for i in self._index_parts)
        self._part_ids = [[ids(atoms) for atoms in p.per_agent] for p in spec.parts]  # [part][agent]
        self._part_sizes = [len(p.atoms) for p in spec.parts]
        # a Box or Dict observation: every agent's numbers in one compiled call (observe_kernel.py)
        self.observation_program = ObservationProgram(spec, self._part_ids) \
            if spec.space in ("Box", "Dict") else None
        self._observer = None if self.observation_program is None else \
            ObservationReader(self.observation_program, spec, self._part_ids, worlds)
        self._numbers_stale = True  # every agent's numbers are read once per engine state (several agents)
        self._scaled = [(ids(a for a, _ in pairs), np.array([v for _, v in pairs], np.float64))
                        for pairs in spec.reward_scaled]
        self._any_scaled = any(ids.size for ids, _ in self._scaled)
        n = self.n_agents
        mask_ids = np.concatenate([ids(m) for m in spec.mask]) if spec.mask is not None else np.zeros(0, np.int64)
        self._has_mask = spec.mask is not None
        # the index parts' first true atoms are read in the fused step only where something uses them: a
        # Discrete or MultiDiscrete space, or a part whose -1 is an error (a Box or Dict has its numbers
        # from the observer; the war game's 5v5 batch spent more on them than on the rest of its reads)
        read_index = self._index_parts if spec.space in ("Discrete", "MultiDiscrete") or self._index_checked else []
        part_ptr, part_atoms, _ = fused.csr([self._part_ids[i][a] for a in range(n) for i in read_index], [])
        table = [(atom, value, a) for a, pairs in enumerate(spec.reward_table) for atom, value in pairs]
        table_ids = ids(t[0] for t in table)
        # each step's reward by term, read in the same compiled call where a recorder keeps them
        # (keep_reward_terms): per agent, the table's atoms (their truth), then the scaled atoms (their bound)
        scaled = [ids for ids, _ in self._scaled], [scales for _, scales in self._scaled]
        scaled_ids, scales = (np.concatenate(x).reshape(n, -1) if x else np.zeros((n, 0)) for x in scaled)
        term_atoms = np.concatenate([table_ids.reshape(n, -1), scaled_ids], axis=1).astype(np.int64)
        n_table = table_ids.size // max(n, 1)
        term_is_table = np.broadcast_to(np.arange(term_atoms.shape[1]) < n_table, term_atoms.shape).astype(np.int8)
        self._keep_terms = np.zeros(1, np.int64)  # keep_reward_terms, for the compiled step
        self._keeps_terms = False
        self._reads = (part_ptr, part_atoms, table_ids, np.array([t[1] for t in table], np.float64),
                       np.array([t[2] for t in table], np.int64), ids(spec.terminated), ids(spec.truncated),
                       mask_ids)
        self._term_reads = (term_atoms.reshape(-1), term_is_table.reshape(-1), self._keep_terms)
        self.reward_term_values = np.concatenate([self._reads[3].reshape(n, -1), scales], axis=1)  # per occurrence
        # read_step's results: indices [agent * index parts], rewards [agent], ends, masks, a paused world,
        # the reward terms' quantities [agent * term]
        self._out = (np.zeros(n * len(read_index), np.int64), np.zeros(n), np.zeros(2),
                     np.zeros(len(mask_ids), np.int8), np.zeros(1, np.int64), np.zeros(term_atoms.size))
        self._quantities = self._out[5].reshape(term_atoms.shape)  # a view: [agent, term]
        board = spec.board
        self._piece_ids: list[tuple[str, str, np.ndarray, np.ndarray, int, list[str], np.ndarray]] | None = None
        self._marks = [] if board is None else \
            [(pred, np.array([eng.atom(pred, c) for c in board.cells], np.int64)) for pred in board.marks]
        self._tables = self._step_tables()
        eng.step()  # t = 0: the program's and the board's facts
        self._snapshot = eng.snapshot()
        self._binding = fused.FusedBinding(eng, self._tables, self._ext, self._reads + self._term_reads,
                                             self._out)
        for drawer in self._choices:
            drawer.freeze(self)
        # picks per draw of the fused tables: the step's random facts, then the start's choices and facts
        self._picks = np.full(len(self._tables[3]), -1, np.int64)
        self._start_picks = self._picks.copy()
        self._start_picks[-1] = 0  # the start facts: a draw with one value
        self.steps = 0
        self.last_rewards = [0.0] * self.n_agents
        # a recorder's: what each term of each step's reward is of [agent, term] (spec.reward_terms: a table
        # atom's occurrence, a scaled atom's bound) in `last_reward_quantities`; its value, last_reward_terms
        self.last_reward_quantities: np.ndarray | None = None
        # one world on the counting kernel stays on it (only a lanes engine moves to counting)
        self._fused = eng.kernel == "counting"
        self._single_index = spec.space == "Discrete" and len(spec.parts) == 1
        self._ends = (False, False)

    def _step_tables(self) -> tuple[np.ndarray, ...]:
        """fused.py's tables of the step facts, and its row buffers (room for every fact on and off)."""
        act_ptr, act_atoms, act_bnd = fused.csr(self._action_ids, self._action_bounds)
        drawers = (*self._before, *self._after, *self._choices)
        # the computed facts' groups after the draws' (their picks from computed_base), the start facts last
        self.computed_base = len(drawers)
        groups = [d.value_ids for d in drawers] + self._computed.value_ids + [[self._start_ids]]
        bounds = [d.value_bounds for d in drawers] + self._computed.value_bounds + [[self._start_bounds]]
        draw_base = np.cumsum([0] + [len(g) for g in groups])[:-1].astype(np.int64)
        val_ptr, val_atoms, val_bnd = fused.csr([v for g in groups for v in g], [v for b in bounds for v in b])
        cap = self.n_agents * max((len(a) for a in self._action_ids), default=0) + \
            sum(max((len(v) for v in g), default=0) for g in groups) + 1
        self._ext = (np.zeros(2, np.int64), np.zeros((2 * cap, 3), np.int64), np.zeros((2 * cap, 2)))
        return (act_ptr, act_atoms, act_bnd, draw_base, val_ptr, val_atoms, val_bnd, np.zeros(cap, np.int64),
                np.zeros(1, np.int64), np.zeros(cap, np.int64), np.zeros((cap, 2)))

    def _ids(self, atoms: Any) -> np.ndarray:
        return np.array([self.engine.atom(a.pred, *a.args) for a in atoms], np.int64)

    # ---- episode ----

    def reset(self, rng: np.random.Generator) -> None:
        self.engine.restore(self._snapshot, np.array([0]))
        picks, first = self._start_picks, len(self._before) + len(self._after)
        for k, drawer in enumerate(self._choices):
            picks[first + k] = drawer.pick(self, rng)
        prev_n = self._tables[8]
        prev_n[0] = 0  # the snapshot has every step fact false
        self._rows[:] = -1
        self._fused_step(self._rows, picks)
        prev_n[0] = 0  # the start's facts stay: the next step does not turn them off
        self._rewards()  # the ends as they stand at the start
        self.steps = 0

    def step(self, actions: Any, rng: np.random.Generator | None, draws: Any = None) -> None:
        """Set each agent's action's facts (`actions`: one index per agent, -1 for none, or an int for one
        agent) and
        this step's random facts, step the engine (twice when an `after` random fact is drawn); the
        step's rewards, one per agent, are then `last_rewards`. `draws`: the value index of each random
        fact drawn before the step, in the spec's order, instead of drawing them from `rng` (to enumerate a
        world's transitions: tracelab/train/tabular.py)."""
        rows = self._rows
        if self.n_agents == 1:
            rows[0] = actions
        else:  # an agent's -1: it does nothing this step
            a = np.asarray(actions, np.int64)
            rows[:] = np.where(a >= 0, a + np.arange(self.n_agents) * self.n_actions, -1)
        picks = self._picks  # the `after` draws' slots stay -1 between steps
        for d, drawer in enumerate(self._before):
            picks[d] = drawer.pick(self, rng) if draws is None else draws[d]
        if len(self._computed):
            base = self.computed_base
            picks[base:base + len(self._computed)] = self._computed.picks(self.engine, np.array([self.steps]))[0]
        self._fused_step(rows, picks)
        rewards = self._rewards()
        terms = self._reward_quantities() if self._keeps_terms else None
        if self._after:
            n_before = len(self._before)
            picks[:n_before] = -1
            for d, drawer in enumerate(self._after, start=n_before):
                if self.true(drawer.after)[0]:
                    picks[d] = drawer.pick(self, rng)
            if picks[n_before:].max() >= 0:
                rows[:] = -1
                self._fused_step(rows, picks)
                rewards = [a + b for a, b in zip(rewards, self._rewards())]
                if terms is not None:
                    terms += self._reward_quantities()
                picks[n_before:] = -1
        self.last_rewards = rewards
        self.last_reward_quantities = terms
        self.steps += 1

    def _fused_step(self, rows: np.ndarray, picks: np.ndarray) -> None:
        eng = self.engine
        self._numbers_stale = True
        if not self._fused:  # the engine's own step, then the reads
            self._unfused_step(rows, picks)
            return
        status = self._binding.call(fused.fused_step, rows, picks, eng.t, eng.next_external_id())
        ext_ptr, ext_i, ext_f = self._ext
        eng.finish_fused_step(status, int(self._out[4][0]), ext_ptr, ext_i, ext_f)
        if status != fused.STATUS_OK:  # the kernel paused (buffer room) and finish went on: read now
            fused.read_step(self._binding.buffers())

    def _unfused_step(self, rows: np.ndarray, picks: np.ndarray) -> None:
        """The fused step's work with the engine's own calls (lanes or compiled kernel)."""
        t = self._tables
        act_ptr, act_atoms, act_bnd, draw_base, val_ptr, val_atoms, val_bnd, prev, prev_n = t[:9]
        now, bnd = [np.zeros(0, np.int64)], [np.zeros((0, 2))]
        for action in rows[rows >= 0]:
            now.append(act_atoms[act_ptr[action]:act_ptr[action + 1]])
            bnd.append(act_bnd[act_ptr[action]:act_ptr[action + 1]])
        for d, p in enumerate(picks):
            if p >= 0:
                v = draw_base[d] + p
                now.append(val_atoms[val_ptr[v]:val_ptr[v + 1]])
                bnd.append(val_bnd[val_ptr[v]:val_ptr[v + 1]])
        new = np.concatenate(now)
        again = set(new.tolist())
        off = np.array([a for a in prev[:prev_n[0]].tolist() if a not in again], np.int64)
        self._step_engine(np.concatenate([off, new]), np.concatenate([np.zeros((len(off), 2)), *bnd]))
        prev[:len(new)] = new
        prev_n[0] = len(new)
        self._read_unfused()

    def _read_unfused(self) -> None:
        part_ptr, part_atoms, table_atoms, table_values, table_agent, term_atoms, trunc_atoms, mask_atoms = \
            self._reads
        reward_atoms, reward_is_table, keep_terms = self._term_reads
        index, rewards, res, mask, _, quantities = self._out
        if keep_terms[0]:  # read_step's quantities: a table atom's truth, a scaled atom's lower bound
            bound = self.engine.lower[0, reward_atoms]
            quantities[:] = np.where(reward_is_table == 1, bound == 1.0, bound)
        for p in range(len(part_ptr) - 1):
            hit = self.true(part_atoms[part_ptr[p]:part_ptr[p + 1]])
            index[p] = int(np.argmax(hit)) if hit.any() else -1
        rewards[:] = np.bincount(table_agent, table_values * self.true(table_atoms), self.n_agents) \
            if len(table_atoms) else 0.0
        res[0] = float(len(term_atoms) > 0 and self.true(term_atoms).any())
        res[1] = float(len(trunc_atoms) > 0 and self.true(trunc_atoms).any())
        mask[:] = self.true(mask_atoms) if len(mask_atoms) else 0

    def _step_engine(self, atoms: np.ndarray, bounds: np.ndarray) -> None:
        eng = self.engine
        n = len(atoms)
        rows = np.empty((n, 3), np.int64)
        rows[:, 0] = atoms
        rows[:, 1] = 0
        rows[:, 2] = eng.next_external_id() + np.arange(n)
        eng.step(external=(np.array([0, n], np.int64), rows, np.ascontiguousarray(bounds, np.float64)))

    # ---- a world's whole state, to come back to (the engine's snapshot and what the env keeps beside it)

    def save_state(self) -> tuple[Any, ...]:
        """Everything the next step depends on, except the random draws: restore it with load_state."""
        prev, prev_n = self._tables[7], self._tables[8]
        return (self.engine.snapshot(), prev[:prev_n[0]].copy(), self.steps, list(self.last_rewards),
                self._ends, tuple(o.copy() for o in self._out))

    def load_state(self, state: tuple[Any, ...]) -> None:
        snap, prev, self.steps, rewards, self._ends, out = state
        self.engine.restore(snap, np.array([0]))
        self._numbers_stale = True
        self._tables[7][:len(prev)] = prev
        self._tables[8][0] = len(prev)
        self.last_rewards = list(rewards)
        for mine, saved in zip(self._out, out):
            mine[:] = saved

    # ---- reading ----

    def true(self, ids: np.ndarray) -> np.ndarray:
        return self.engine.is_true(ids)[0]

    def observation(self, agent: int = 0) -> Any:
        """Agent `agent`'s observation in the spec's space (gym_env.observation_space)."""
        spec = self.spec
        if self._single_index:  # the toy-text games' case, kept short
            value = int(self._out[0][agent])
            if value >= 0:
                return value
        n_index = len(self._index_parts)
        indices = self._out[0][agent * n_index:(agent + 1) * n_index]
        for p, i in enumerate(indices.tolist() if self._index_checked else ()):
            part = spec.parts[self._index_parts[p]]
            if i < 0 and part.missing is None:
                raise no_index(spec, part)
        if spec.space == "Discrete":
            value = 0
            for size, i in zip(self._part_sizes, indices.tolist()):  # ravel_multi_index, first part slowest
                value = value * size + i
            return value
        if spec.space == "MultiDiscrete":
            return indices.astype(np.int64)
        width = self.observation_program.width
        if self._numbers_stale:
            self._observer.read(self.engine)
            self._numbers_stale = False
        numbers = self._observer.numbers[0, agent * width:(agent + 1) * width].copy()
        if spec.space == "Box":
            return numbers
        parts = split_parts(spec, numbers[None])
        return {p.name: (int(v[0, 0]) if p.is_discrete else v[0]) for p, v in zip(spec.parts, parts)}

    def _rewards(self) -> list[float]:
        """The engine step's rewards, one per agent; also keeps the ends (read_step's flags)."""
        terminated, truncated = self._out[2].tolist()
        self._ends = (terminated == 1.0, truncated == 1.0)
        rewards = self._out[1].tolist()
        if self._any_scaled:
            for a, (ids, scales) in enumerate(self._scaled):
                rewards[a] += float((self.engine.lower[0, ids] * scales).sum())
        return rewards

    @property
    def keep_reward_terms(self) -> bool:
        """Whether each step reads its reward terms' quantities (last_reward_quantities): a recorder's,
        or a decomposed learner's."""
        return self._keeps_terms

    @keep_reward_terms.setter
    def keep_reward_terms(self, keep: bool) -> None:
        self._keeps_terms = bool(keep)
        self._keep_terms[0] = int(keep)  # the compiled step's flag (read_step)

    def _reward_quantities(self) -> np.ndarray:
        """The engine step's reward terms' quantities [agent, term], as the step read them (read_step: a
        table atom's truth, a scaled atom's bound, so a term worth 0 shows it occurred): a copy, kept by a
        recorder (the values are these times reward_term_values, taken when read)."""
        return self._quantities.copy()

    @property
    def last_reward_terms(self) -> np.ndarray | None:
        """The last step's reward by term [agent, term] (its quantities times the terms' values; they add up
        to last_rewards), where the world keeps them (keep_reward_terms)."""
        q = self.last_reward_quantities
        return None if q is None else q * self.reward_term_values

    def terminated(self) -> bool:
        return self._ends[0]

    def outcome(self) -> str:
        """How the episode ended, after its last step: "win" or "loss" when the spec's `[end] win` or
        `loss` atom holds at a termination (a win first), else "terminated" or "truncated"."""
        if self._ends[0]:
            for name, ids in (("win", self._win_ids), ("loss", self._loss_ids)):
                if ids.size and self.true(ids).any():
                    return name
        return "terminated" if self._ends[0] else "truncated"

    def truncated(self) -> bool:
        """A truncated atom, or the spec's step limit reached by a step that did not terminate (a game won
        on its last step is won, not cut short)."""
        limit = self.spec.max_steps
        return (limit is not None and self.steps >= limit and not self._ends[0]) or self._ends[1]

    def action_mask(self, agent: int = 0) -> np.ndarray | None:
        if not self._has_mask:
            return None
        return self._out[3][agent * self.n_actions:(agent + 1) * self.n_actions].copy()

    def pieces_now(self) -> list[tuple[str, str, int, int, bool, str]]:
        """The board's pieces standing now, as (kind, thing, row, col, alive, heading: "" without one), each
        thing on the first cell where its `at` atom holds (a thing on no cell is left out)."""
        board = self.spec.board
        if board is None or not board.pieces:
            return []
        if self._piece_ids is None:
            self._piece_ids = self._piece_atoms()
        out = []
        for kind, thing, cells, at_ids, alive_id, headings, heading_ids in self._piece_ids:
            on = np.flatnonzero(self.true(at_ids))
            if not on.size:
                continue
            row, col = divmod(int(cells[on[0]]), board.width)
            alive = alive_id < 0 or bool(self.true(np.array([alive_id]))[0])
            held = np.flatnonzero(self.true(heading_ids))
            out.append((kind, thing, row, col, alive, headings[held[0]] if held.size else ""))
        return out

    def _piece_atoms(self) -> list[tuple[str, str, np.ndarray, np.ndarray, int, list[str], np.ndarray]]:
        """Each piece's known atoms (looked up, never interned): its cells with at(Thing, Cell), alive(Thing)
        (-1 without), the headings with heading(Thing, D)."""
        eng, board = self.engine, self.spec.board
        out = []
        for kind, spec in board.pieces.items():
            for binding, _ in eng.match(f"{spec.things}(X)"):
                thing = binding["X"]
                at = [(k, eng.known_atom(spec.at, thing, c)) for k, c in enumerate(board.cells)]
                at = [(k, aid) for k, aid in at if aid is not None]
                alive = eng.known_atom(spec.alive, thing) if spec.alive else None
                heads = [(d, eng.known_atom(spec.heading, thing, d)) for d in DIRECTION_ARROWS] if spec.heading else []
                heads = [(d, aid) for d, aid in heads if aid is not None]
                out.append((kind, thing, np.array([k for k, _ in at], np.int64), np.array([a for _, a in at], np.int64),
                            -1 if alive is None else alive, [d for d, _ in heads],
                            np.array([a for _, a in heads], np.int64)))
        return out

    def marked_cells(self) -> dict[str, str]:
        """Board cell -> the `marks` predicate true there (the last one written, when several are)."""
        cells = self.spec.board.cells if self.spec.board is not None else []
        return {cells[k]: pred for pred, aids in self._marks for k in np.flatnonzero(self.true(aids))}


def _bounds(atoms: tuple[Atom, ...]) -> np.ndarray:
    return np.array([[a.lower, a.upper] for a in atoms], np.float64).reshape(len(atoms), 2)
