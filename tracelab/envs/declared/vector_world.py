"""A batch of declared worlds on ONE engine (from 64 worlds the lanes kernel, below it the counting kernel
inside one compiled call with the reads, vector_fused.py), each world with its own np_random, and
episodes that restart one world at a time.

Resets without an engine step (docs/worlds.md, "256 worlds: the vector env"): a declared episode starts with an
engine step (the start facts and the drawn start choices), but the engine steps every world at once. So
the start of every possible outcome of the start choices (the product of their possible values: one for
FrozenLake's and CliffWalking's maps, 300 for Taxi) is computed once, when the batch is built, a batch of
worlds at a time, and kept as engine snapshots; a world that restarts draws its choices from its own
np_random exactly as a single DeclaredWorld does, then takes the state of its outcome's world in those
snapshots (Engine.restore(..., source=...)). The outcomes' states are bounded (MAX_START_BYTES)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from tracelab.engine.core import LANES_MIN_WORLDS
from tracelab.envs.declared import fused, vector_fused
from tracelab.envs.declared.observe import missing_index
from tracelab.envs.declared.observe_kernel import split_parts
from tracelab.envs.declared.spec import WorldSpec
from tracelab.envs.declared.state_errors import no_index, no_weights_hold
from tracelab.envs.declared.spec_size import check_worlds
from tracelab.envs.declared.world import DeclaredWorld

MAX_START_BYTES = 256 << 20  # the start outcomes' engine states, all together


class DeclaredWorlds:
    """`n_worlds` worlds of `spec` stepped together (rows: one action per world and agent)."""

    def __init__(self, spec: WorldSpec, n_worlds: int, kernel: str = "auto") -> None:
        after = [d for d in spec.random_facts if d.after is not None]
        if after:
            raise ValueError(f"{spec.path}: random fact {after[0].name!r} is drawn `after` a step, which the "
                             "vector env does not support yet (a second engine step of some worlds only)")
        check_worlds(n_worlds, spec.named_atoms, f"num_envs={n_worlds:,}")  # before the batch's engine
        self.spec = spec
        self.n_worlds = w = n_worlds
        # the single world's construction, on an engine of n_worlds worlds: its ids, draws and tables
        self.one = one = _world(spec, n_worlds, kernel)
        self.engine = one.engine
        self.n_agents, self.n_actions = one.n_agents, one.n_actions
        t = one._tables
        cap = len(t[7])
        self._tables = (*t[:7], np.zeros((w, cap), np.int64), np.zeros(w, np.int64), t[9], t[10])
        self._ext = (np.zeros(w + 1, np.int64), np.zeros((w * 2 * cap, 3), np.int64), np.zeros((w * 2 * cap, 2)))
        part_ptr, part_atoms, table_atoms, table_values, table_agent, term, trunc, mask = one._reads
        read_atoms = np.concatenate([part_atoms, table_atoms, term, trunc, mask]).astype(np.int64)
        self.steps = np.zeros(w, np.int64)  # each world's steps into its episode
        limit = -1 if spec.max_steps is None else spec.max_steps
        self._reads = (read_atoms, np.zeros((w, len(read_atoms)), np.bool_), part_ptr, table_values, table_agent,
                       np.array([len(part_atoms), len(table_atoms), len(term), len(trunc), len(mask), limit],
                                np.int64), self.steps)
        self._out = (np.zeros((w, len(one._out[0])), np.int64), np.zeros((w, self.n_agents)),
                     np.zeros((2, w), np.bool_), np.zeros((w, len(mask)), np.int8), np.zeros(1, np.int64))
        self._picks = np.full((w, len(one._picks)), -1, np.int64)
        # every draw one np_random.random() (the toy-text games): drawn a block at a time (_Uniforms)
        self._only_uniforms = all(d.draw.method == "categorical" for d in (*one._choices, *one._before)) and \
            all(d.weight_ids is None for d in one._before)
        # every draw of fixed probabilities: a draw with no weights never freezes (world._Drawer), so this
        # holds for good and is not asked again each step (60 draws a 20v20 step); then the compiled step
        # draws them (vector_fused.draw_rows)
        self._categorical = _CategoricalTable(one._before) \
            if self._only_uniforms and _CategoricalTable.holds(one._before) else None
        # a block of several steps' numbers: a 20v20 step draws 60, which a 64-number block refilled every step;
        # a refill costs ~10-30 µs of Python, so a small batch (a one-world 5v5 step is ~150 µs) keeps 64
        # steps' numbers (at most 64 * 64 steps' numbers in all: ~2 MB at 20v20)
        block = max(64, (8 if w >= LANES_MIN_WORLDS else 64) * len(one._before))
        self._uniform_arrays = (np.empty((w, block)), np.full(w, block, np.int64))  # filled on first use
        self.uniforms: _Uniforms | None = None
        self._observer = one._observer  # built for the engine's n_worlds worlds
        self._numbers_read = False  # whether the observer's numbers are every agent's as the engine stands
        # the compiled step reads every agent's numbers but a `lower` or `bounds` part's (numpy's, after it)
        self._observed = self._observer is not None and not self._observer.program.python_parts
        table = self._categorical or _CategoricalTable([])
        self._draws = np.array([vector_fused.DRAW_GIVEN, len(one._before), 1], np.int64)
        observe = self._observer.arrays if self._observer is not None else _no_observation(w)
        self._batch = (self._draws, *self._uniform_arrays, table.cumulative, table.sizes,
                       np.arange(self.n_agents, dtype=np.int64) * self.n_actions,  # agent i's first action row
                       np.full((w, self.n_agents), -1, np.int64), self._picks, observe, self.steps,
                       np.zeros(2, np.int64))  # the step's clock: vector_fused.step_worlds
        self._binding = fused.FusedBinding(self.engine, self._tables, self._ext, self._reads, self._out, self._batch)
        # per-agent views of the reads, made once: a reader called per agent and step (an env's obs and
        # reward of each agent) pays a slice's copy, not the slicing and lookups around it as well
        self._reward_columns = [self._out[1][:, a] for a in range(self.n_agents)]
        self._ends = (self._out[2][0], self._out[2][1])
        n_index = len(one._index_parts)
        self._index_columns = [self._out[0][:, a * n_index:(a + 1) * n_index] for a in range(self.n_agents)]
        width = one.observation_program.width if one.observation_program is not None else 0
        numbers = self._observer.numbers if self._observer is not None else np.zeros((w, 0), np.float32)
        self._number_views = [numbers[:, a * width:(a + 1) * width] for a in range(self.n_agents)]
        self._scaled = self.one._scaled if self.one._any_scaled else None
        self._computed = self.one._computed if len(self.one._computed) else None
        self._box_numbers = spec.space == "Box" and not one._index_checked  # observations(): numbers only
        self._starts = _StartOutcomes(self)

    @property
    def kernel(self) -> str:
        return self.engine.kernel

    # ---- the engine step of every world ----

    def engine_step(self, actions: np.ndarray, picks: np.ndarray) -> None:
        """One engine step of every world outside their episodes (a start's: it does not count in `steps`),
        then the reads: actions int64 [W, agents] (-1: none), every group's value picks [W, groups] (-1:
        none)."""
        self._picks[:] = picks
        self._draws[0] = vector_fused.DRAW_GIVEN
        self._draws[2] = 0
        try:
            self._step_engine(actions)
        finally:
            self._draws[2] = 1
            self._picks[:] = -1  # a step sets only its draws' and computed facts' groups

    def _step_engine(self, actions: np.ndarray) -> None:
        eng = self.engine
        self._numbers_read = False
        ext_ptr, ext_i, ext_f = self._ext
        if eng.kernel != "counting":  # lanes (or compiled): the engine's own step, then the reads
            k = vector_fused.prepare_batch(self._tables, self._ext, self._batch, actions, eng.next_external_id())
            eng.step(external=(ext_ptr, ext_i[:k], ext_f[:k]))
            self._read()
            return
        clock = self._batch[10]
        clock[0], clock[1] = eng.t, eng.next_external_id()
        status = self._binding.call(vector_fused.step_worlds, actions)
        eng.finish_fused_step(status, int(self._out[4][0]), ext_ptr, ext_i, ext_f)
        if status != vector_fused.STATUS_OK:  # the kernel paused (buffer room) and finish went on: read now
            self._read()
        else:  # every agent's numbers came with the step, but a `lower` or `bounds` part's
            self._numbers_read = self._observed

    def _read(self) -> None:
        self._numbers_read = False
        if self.engine.kernel == "counting":
            vector_fused.read_batch(self._binding.buffers())
        else:
            vector_fused.read_truth(self.engine.is_true(self._reads[0]), self._reads, self._out)

    # ---- episodes ----

    def use_generators(self, rngs: list[np.random.Generator]) -> None:
        """Each world's np_random, from which its draws come from now on."""
        if len(rngs) != self.n_worlds:
            raise ValueError(f"{len(rngs)} generators for {self.n_worlds} worlds")
        self.rngs = rngs
        self._randoms = [r.random for r in rngs]  # bound once: a step draws one number per world
        self.uniforms = _Uniforms(rngs, *self._uniform_arrays) if self._only_uniforms else None

    def reset(self, worlds: np.ndarray) -> None:
        """Restart `worlds` (int64 indices): each draws its start choices from its generator; then the
        reads of every world are refreshed (the others' are unchanged)."""
        self._starts.restore(worlds, self)
        self._tables[8][worlds] = 0  # a start's facts stay: the next step does not turn them off
        self.steps[worlds] = 0
        self._read()

    def step(self, actions: np.ndarray) -> None:
        """Every world plays actions[w] (one agent), or actions[w, i] for agent i (several; -1: none), and
        draws this step's random facts from its generator."""
        actions = _call_layout(actions).reshape(self.n_worlds, -1)  # agent i's row: vector_fused.draw_rows
        picks, before = self._picks, self.one._before
        if self._categorical is not None and self.uniforms is not None:  # drawn in the compiled step
            self.uniforms.make_room(len(before))
            self._draws[0] = vector_fused.DRAW_UNIFORMS
        else:
            self._draws[0] = vector_fused.DRAW_GIVEN
            # every draw one random() a world: the step's numbers of all draws taken at once, in the spec's order
            u = self.uniforms.each(len(before)) if self.uniforms is not None and before else None
            for d, drawer in enumerate(before):
                picks[:, d] = _draw_batch(drawer, self, None if u is None else u[:, d])
        computed = self._computed
        if computed is not None:
            base = self.one.computed_base
            picks[:, base:base + len(computed)] = computed.picks(self.engine, self.steps)
        self._step_engine(actions)  # counts the step in `steps` before its reads (vector_fused.draw_rows)

    # ---- reading (after a step or a reset) ----

    def rewards(self, agent: int = 0) -> np.ndarray:
        r = self._reward_columns[agent].copy()
        if self._scaled is not None:
            ids, scales = self._scaled[agent]
            if ids.size:
                r += self.engine.lower[:, ids] @ scales
        return r

    def holds(self, atoms: np.ndarray) -> np.ndarray | None:
        """bool [W, len(atoms)]: where each atom holds (the spec's per-agent `[agents] decides`, `alive`);
        None for no atoms (the spec does not declare them)."""
        return self.engine.is_true(atoms) if atoms.size else None

    def terminated(self) -> np.ndarray:
        return self._ends[0].copy()

    def won(self) -> np.ndarray:
        """Per world: terminated with one of the spec's `[end] win` atoms [1,1] (DeclaredWorld.outcome)."""
        ids = self.one._win_ids
        return self.terminated() & self.engine.is_true(ids).any(axis=1) if ids.size else np.zeros(self.n_worlds, bool)

    def outcomes(self) -> np.ndarray:
        """Per world, after its last step: "win" or "loss" when one of the spec's `[end] win` or `loss`
        atoms holds at a termination (a win first), else "terminated" or "truncated"
        (DeclaredWorld.outcome's names; read for the worlds whose episode just ended)."""
        term = self.terminated()
        out = np.where(term, "terminated", "truncated").astype("<U10")
        lost = term & self.engine.is_true(self.one._loss_ids).any(axis=1) if self.one._loss_ids.size else \
            np.zeros(self.n_worlds, bool)
        out[lost] = "loss"
        out[self.won()] = "win"
        return out

    def truncated(self, limit: int | None) -> np.ndarray:
        """A truncated atom, or the spec's step limit reached in a world that did not terminate (both read
        with the step: vector_fused.read_truth), or `limit` (a TimeLimit's, which truncates whatever the
        step did) reached."""
        out = self._ends[1].copy()
        if limit is not None:
            out |= self.steps >= limit
        return out

    def action_masks(self, agent: int = 0) -> np.ndarray | None:
        if self.spec.mask is None:
            return None
        return self._out[3][:, agent * self.n_actions:(agent + 1) * self.n_actions].copy()

    def observations(self, agent: int = 0) -> Any:
        """Agent `agent`'s observation of every world: an array with a world axis (a dict of them for a
        Dict space), as gymnasium's batch_space lays it out."""
        if self._box_numbers:  # the usual case, first
            return self._agent_numbers(agent)
        one, spec = self.one, self.spec
        index = self._index_columns[agent]
        if one._index_checked and index.min() < 0:  # which part misses its atom
            for p in range(index.shape[1]):
                part = spec.parts[one._index_parts[p]]
                if missing_index(part, index[:, p]):
                    w = int(np.flatnonzero(index[:, p] < 0)[0])
                    raise no_index(spec, part, w)
        if spec.space == "Discrete":
            value = np.zeros(self.n_worlds, np.int64)
            for size, col in zip(one._part_sizes, index.T):  # first part slowest, as observation()
                value = value * size + col
            return value
        if spec.space == "MultiDiscrete":
            return index.astype(np.int64)
        numbers = self._agent_numbers(agent)
        if spec.space == "Box":
            return numbers
        parts = split_parts(spec, numbers)
        return {p.name: (v[:, 0].astype(np.int64) if p.is_discrete else v) for p, v in zip(spec.parts, parts)}

    def _agent_numbers(self, agent: int) -> np.ndarray:
        """A copy of agent `agent`'s observed numbers [W, width]; every agent's come from one read of the
        engine (until it changes)."""
        if not self._numbers_read:
            self._read_numbers()
        return self._number_views[agent].copy()

    def _read_numbers(self) -> None:
        """Every agent's numbers into the observer's buffer (which the per-agent views look at)."""
        self._observer.read(self.engine)
        self._numbers_read = True


def _world(spec: WorldSpec, n_worlds: int, kernel: str) -> DeclaredWorld:
    """The batch's DeclaredWorld; kernel "auto": the bit-parallel lanes kernel from a word of worlds on
    (the engine's own rule, ~3-5x faster than counting on the toy-text games), for a crisp program."""
    if kernel != "auto":
        return DeclaredWorld(spec, kernel=kernel, worlds=n_worlds)
    if n_worlds >= LANES_MIN_WORLDS:
        try:
            return DeclaredWorld(spec, kernel="lanes", worlds=n_worlds)
        except ValueError as e:
            if "crisp" not in str(e):
                raise
    return DeclaredWorld(spec, kernel="counting", worlds=n_worlds)


def _call_layout(a: np.ndarray) -> np.ndarray:
    """`a` as a writeable C-ordered int64 array: the one array type the compiled step is compiled for (another
    layout would compile it again, with the engine's kernel in it: minutes)."""
    a = np.asarray(a)
    if a.dtype == np.int64 and a.flags.c_contiguous and a.flags.writeable:
        return a
    return np.array(a, np.int64, order="C")


def _no_observation(n_worlds: int) -> tuple[np.ndarray, ...]:
    """ObservationReader.arrays of no observation program (a Discrete or MultiDiscrete space's)."""
    return (np.zeros(0, np.int64), np.zeros((n_worlds, 0), np.bool_), np.zeros((0, 6), np.int64), np.zeros(0),
            np.zeros(0, np.float32), np.zeros((0, 3), np.int64), np.zeros((n_worlds, 0), np.float32))


def _draw_batch(drawer: Any, worlds: DeclaredWorlds, u: np.ndarray | None = None) -> np.ndarray:
    """One value of `drawer` per world, each from its world's generator, exactly as _Drawer.pick draws
    for one world (categorical: one random() u, the first value whose cumulative probability exceeds u,
    else 0; choice: one integers(0, n)). `u`: a categorical draw's numbers, already taken."""
    d, rngs = drawer.draw, worlds.rngs
    if drawer.weight_ids is None and drawer.possible is None:
        if d.method == "choice":
            n = len(drawer.value_ids)
            return np.array([r.integers(0, n) for r in rngs], np.int64)
        cumulative = np.asarray(drawer.cumulative)
        if u is None:
            u = worlds.uniforms.each(1)[:, 0] if worlds.uniforms is not None else \
                np.array([random() for random in worlds._randoms])
        picks = np.searchsorted(cumulative, u, side="right")
        picks[picks == len(cumulative)] = 0
        return picks.astype(np.int64)
    # weights read in each world's state now (none of the toy-text games draws so during a step)
    w = drawer.weight_ids
    ok = worlds.engine.is_true(w.ravel()).reshape(worlds.n_worlds, *w.shape).all(axis=2)
    out = np.empty(worlds.n_worlds, np.int64)
    for i, r in enumerate(rngs):
        possible = np.flatnonzero(ok[i])
        if possible.size == 0:
            raise no_weights_hold(worlds.spec, d, i)
        if d.method == "choice":
            out[i] = possible[r.integers(0, possible.size)]
        else:
            cumulative = np.cumsum(ok[i] / ok[i].sum())
            out[i] = int(np.argmax(cumulative > r.random())) if (cumulative > 0).any() else 0
    return out


class _CategoricalTable:
    """The step's categorical draws of fixed probabilities, as the compiled step draws them for all worlds
    (vector_fused.draw_rows): _draw_batch's searchsorted (side="right": how many cumulative sums are <= u;
    past the last one, value 0) for every draw together, the cumulative sums padded with +inf so that a
    shorter draw counts none of the padding."""

    def __init__(self, drawers: list[Any]) -> None:
        sums = [d.cumulative or [] for d in drawers]
        self.cumulative = np.full((len(sums), max((len(c) for c in sums), default=0)), np.inf)
        for d, c in enumerate(sums):
            self.cumulative[d, :len(c)] = c
        self.sizes = np.array([len(c) for c in sums], np.int64)

    @staticmethod
    def holds(drawers: list[Any]) -> bool:
        """Whether every draw has fixed probabilities (none weighed by the state)."""
        return all(d.weight_ids is None and d.possible is None and d.cumulative is not None for d in drawers)



def _nbytes(snapshot: Any) -> int:
    """The arrays' bytes in an engine snapshot (a dict of arrays, lists and scalars)."""
    if isinstance(snapshot, np.ndarray):
        return snapshot.nbytes
    if isinstance(snapshot, dict):
        return sum(_nbytes(v) for v in snapshot.values())
    if isinstance(snapshot, (list, tuple)):
        return sum(_nbytes(v) for v in snapshot)
    return 0


class _Uniforms:
    """Each world's next np_random.random() numbers, a block at a time: Generator.random(n) gives the numbers
    n calls of random() give, one after another (both take next_double of the bit generator), so a world
    whose every draw is one random() draws exactly what it would call by call, for one call per block (at
    least 64, or `block`)."""

    def __init__(self, rngs: list[np.random.Generator], buf: np.ndarray, pos: np.ndarray) -> None:
        """`buf` [worlds, block], `pos` [worlds]: the arrays the numbers are kept in (the compiled step's)."""
        self.rngs = rngs
        self.buf, self.pos = buf, pos
        self.block = buf.shape[1]
        pos[:] = self.block  # empty: filled on first use
        self.low = 0  # every world has at least this many numbers left
        self._every = np.arange(len(rngs))

    def make_room(self, k: int) -> None:
        """At least k numbers left in every world, which the caller then takes (vector_fused.draw_rows)."""
        if self.low < k:
            for w in np.flatnonzero(self.pos > self.block - k):
                self._fill(w)
            self.low = self.block - int(self.pos.max())
        self.low -= k

    def each(self, k: int) -> np.ndarray:
        """The next k numbers of every world [worlds, k] (k <= block)."""
        self.make_room(k)
        u = self.buf[self._every[:, None], self.pos[:, None] + np.arange(k)]
        self.pos += k
        return u

    def take(self, worlds: np.ndarray) -> np.ndarray:
        """One number for each of `worlds` (distinct indices)."""
        for w in worlds[self.pos[worlds] >= self.block]:
            self._fill(w)
        u = self.buf[worlds, self.pos[worlds]]
        self.pos[worlds] += 1
        self.low -= 1
        return u

    def _fill(self, w: int) -> None:
        """World w's numbers not taken yet, moved to the front, then new ones after them."""
        left = self.block - self.pos[w]
        self.buf[w, :left] = self.buf[w, self.pos[w]:]
        self.buf[w, left:] = self.rngs[w].random(self.block - left)
        self.pos[w] = 0


class _StartOutcomes:
    """Every outcome of the start choices, started once: outcome k's state is world k % W of snapshot
    k // W. An outcome is the choices' values (each among its possible ones), first choice slowest."""

    def __init__(self, worlds: DeclaredWorlds) -> None:
        one, eng, w = worlds.one, worlds.engine, worlds.n_worlds
        self.one = one
        self.drawers = one._choices
        self.values = [d.possible if d.possible is not None else np.arange(len(d.value_ids))
                       for d in self.drawers]  # each choice's possible values
        self.position = [{int(v): i for i, v in enumerate(vals)} for vals in self.values]
        self.sizes = [len(v) for v in self.values]
        self.cumulative = [np.asarray(d.cumulative if d.cumulative is not None else [], np.float64)
                           for d in self.drawers]
        # value -> its position among the possible ones (an impossible value, which categorical's
        # fallback to value 0 can give at probability ~1e-16, counts as the first possible one)
        self.position_of = [np.zeros(len(d.value_ids), np.int64) for d in self.drawers]
        for c, vals in enumerate(self.values):
            self.position_of[c][vals] = np.arange(len(vals))
        self.n = n = math.prod(self.sizes)
        per_world = _nbytes(eng.snapshot()) // w
        batches = -(-n // w)
        if batches * w * per_world > MAX_START_BYTES:
            raise ValueError(f"{worlds.spec.path}: the start choices have {n} outcomes; their engine states "
                             f"({batches * w * per_world >> 20} MiB at {w} worlds) exceed the vector env's "
                             f"{MAX_START_BYTES >> 20} MiB")
        first = len(one._before) + len(one._after)
        start = one._snapshot
        everywhere = np.arange(w)
        rows = np.full((w, worlds.n_agents), -1, np.int64)
        self.snapshots = []
        for b in range(batches):
            picks = np.tile(one._start_picks, (w, 1))
            ks = np.minimum(np.arange(b * w, (b + 1) * w), n - 1)  # the last batch repeats its last outcome
            for c, (vals, idx) in enumerate(zip(self.values, np.unravel_index(ks, self.sizes) if n > 1 else
                                                [np.zeros(w, np.int64)] * len(self.sizes))):
                picks[:, first + c] = vals[idx]
            eng.restore(start, everywhere)
            worlds._tables[8][:] = 0  # the snapshot has every step fact false
            worlds.engine_step(rows, picks)
            self.snapshots.append(eng.snapshot())

    def restore(self, targets: np.ndarray, worlds: DeclaredWorlds) -> None:
        """Worlds `targets` draw their start outcomes (each from its generator) and take their states."""
        one, w, rngs, uniforms = self.one, worlds.n_worlds, worlds.rngs, worlds.uniforms
        outcome = np.zeros(len(targets), np.int64)
        if uniforms is not None:  # every choice is one random() a world: drawn for all targets at once
            for c in range(len(self.drawers)):  # in the spec's order, as DeclaredWorld.reset draws
                value = np.searchsorted(self.cumulative[c], uniforms.take(targets), side="right")
                value[value == len(self.cumulative[c])] = 0  # categorical's "none exceeds u": value 0
                outcome = outcome * self.sizes[c] + self.position_of[c][value]
        else:
            for i, t in enumerate(targets):
                k = 0
                for c, drawer in enumerate(self.drawers):
                    k = k * self.sizes[c] + self.position[c][drawer.pick(one, rngs[t])]
                outcome[i] = k
        if self.n == 1:  # every world of the snapshot holds the one outcome: each takes its own world's
            one.engine.restore(self.snapshots[0], targets)  # (word-parallel; ~7x restoring from a source)
            return
        batch = outcome // w
        for b in np.unique(batch):
            sel = batch == b
            one.engine.restore(self.snapshots[b], targets[sel], outcome[sel] % w)
