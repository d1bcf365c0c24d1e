"""The Engine: a program grounded over a graph, stepped one timestep at a time for a batch of worlds.

Python here only builds integer tables and moves facts in and trace rows out; every timestep is one call
of the compiled kernel (kernel.step_worlds) for all worlds together.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from . import annotations
from . import compile_background
from . import grounding_cache
from . import kernel as K
from .aggregate_tables import aggregate_tables, aggregated_rules
from .backend_compiled import CompiledState, compiled_backend
from .backend_counting import CountingState
from .compile_cache import CacheEntry
from .crisp import crisp_codes
from .errors import FixpointError, InconsistencyError, ProgramCheckError
from .graph import Graph
from .grounding import Grounder, GroundingTable, rule_head_bound
from .kernel_names import KERNELS
from .kernel_tables import AggregateTables, KernelTables
from .memory import release_freed_memory
from .numba_startup import defer_scipy_import
from .parser import check_program, parse_literal
from .program import (
    EPS,
    INCONSISTENCY_POLICIES,
    MAX_BINDING_CLAUSES,
    UPDATE_MODES,
    Fact,
    Program,
    constant_text,
    effective_bound,
    ordered_nodes,
)
from .trace_take import INT32_COLUMNS, take_local_columns
from .vocabulary import Vocabulary
from .notices import library_logger

if TYPE_CHECKING:
    from .backend_lanes import LaneState

# Before the first kernel loads from numba's cache: numba would import scipy.linalg then, unused (about 0.17 s
# of CPU, or a second under load: issue 40). Here, where every Engine's kernels load.
defer_scipy_import()

TRACE_COLUMNS = ("world", "t", "pass_no", "atom", "cause_kind", "cause_id", "grounding", "n_sources",
                 "old_lower", "old_upper", "new_lower", "new_upper")
_TRACE_INT_DTYPES = tuple(np.dtype(d) for d in (np.int32, np.int32, np.int32, np.int32, np.int8, np.int32,
                                                 np.int32, np.int16))
# (column name, dtype, taken as is from the int32 buffer) per int column of take_trace()
_TRACE_INT_OUT = tuple((name, d, d == np.dtype(np.int32)) for name, d in zip(TRACE_COLUMNS, _TRACE_INT_DTYPES))
_TRACE_FLOAT_NAMES = TRACE_COLUMNS[K.TRACE_INT_COLUMNS:]
TRACE_LOCAL_COLUMNS = (*TRACE_COLUMNS, "world_episode")  # take_trace(t_start, episode)
# trace buffers: a step that wrote this many rows hands its buffers to take_trace() instead of a copy
# (at t = 0 a million-fact graph writes a million rows: a copy would double the trace's 64 bytes a row)
TRACE_HANDOVER_ROWS = 65_536
TRACE_MIN_ROWS = 1024
# "auto" takes the lanes kernel for crisp programs from this many worlds on (a word holds 64 worlds)
LANES_MIN_WORLDS = 64
# a running engine checks on its background compile at most this often (one waitpid per check)
BACKGROUND_POLL_S = 0.5
# notices (a requested kernel not used: warning; a background compile started or taken over: info) go to
# the `tracelab` loggers; the library prints nothing, the CLI shows them on stderr
log = library_logger(__name__)
STAT_NAMES = ("firings", "rederivations", "static_ignored", "changes", "passes", "watch_visits",
              "candidates")


def _trace_buffers(rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Empty trace buffers of `rows` rows (int32 [rows, 8], float64 [rows, 4]) stored column by column:
    the kernel writes a row across the columns, take_trace() reads each column as one block. Always
    Fortran-ordered (rows >= 2), so the kernel is compiled for one layout."""
    rows = max(rows, 2)
    return (np.empty((K.TRACE_INT_COLUMNS, rows), np.int32).T,
            np.empty((K.TRACE_FLOAT_COLUMNS, rows), np.float64).T)


class Engine:
    """Runs `program` on `graph` for `worlds` independent worlds (same program, same vocabulary)."""

    def __init__(self, program: Program, graph: Graph | None = None, *, worlds: int = 1,
                 trace: bool | Sequence[bool] | np.ndarray = True, max_passes: int = 1000,
                 max_immediate: int = 100_000, trace_rows_per_step: int = 65_536,
                 kernel: str = "auto", threads: int | None = None, background_compile: bool = False,
                 max_groundings: int | None = None, cache_grounding: bool = False) -> None:
        """`max_groundings`: refuse (ProgramError at the rule) a program whose groundings could pass it,
        before they are built; None: the limit of engine/grounding_limit.py (from the machine's memory).
        `cache_grounding`: the groundings made before the first step is taken are read from (or kept in)
        the grounding cache (grounding_cache.py), for a program built again and again (a declared world's)."""
        if worlds < 1:
            raise ValueError(f"worlds must be >= 1, got {worlds}")
        self.program = program
        if graph is not None:  # a predicate with one arity in the program and another in the graph
            check_program(program, graph.predicates())
        self.n_worlds = worlds
        self.t = 0
        self.vocab = Vocabulary(ordered_nodes(program, graph.nodes if graph else ()))
        # graph facts come first in source order (docs/language.md); they stay columns in the graph
        self.graph = graph if graph is not None else Graph()
        self.rules = program.rules
        for r in self.rules:  # programs built in code may skip check_program; the kernel cannot take these
            if sum(c.binds for c in r.body) > MAX_BINDING_CLAUSES:
                raise ProgramCheckError.at(r.loc, f"rule '{r.name}' has more than {MAX_BINDING_CLAUSES} "
                                                  "binding body clauses")
        self.grounder = Grounder(self.rules, self.vocab, program.closed, program.edge_heads, self.graph.edges,
                                 max_groundings)
        self.cache_grounding = cache_grounding
        # user annotation functions, bound now: registering another one later changes nothing here
        self._user_functions: list[tuple[str, object]] = []
        for r in self.rules:
            if r.aggregated and r.immediate:  # check_program says so too; programs built in code may skip it
                raise ProgramCheckError.at(r.loc, f"rule '{r.name}' is immediate: quantifiers and annotation "
                                                  "functions need '<-0' or a delay")
            if r.annotation is not None and not annotations.is_known(r.annotation):
                raise ProgramCheckError.at(r.loc, f"rule '{r.name}': unknown annotation function "
                                                  f"'{r.annotation}' (register it with register_annotation)")
            if r.annotation is not None and r.annotation not in annotations.BUILTINS \
                    and r.annotation not in (n for n, _ in self._user_functions):
                self._user_functions.append((r.annotation, annotations.lookup(r.annotation)))
        self._fact_tables()
        self._rule_tables()
        self._cfg = np.zeros(K.N_CFG, np.int64)
        self._cfg[[K.CFG_MODE, K.CFG_RESET, K.CFG_POLICY, K.CFG_MAX_PASSES, K.CFG_MAX_IMMEDIATE]] = (
            UPDATE_MODES.index(program.mode), int(program.timesteps == "reset"),
            INCONSISTENCY_POLICIES.index(program.inconsistency), max_passes, max_immediate)
        if trace_rows_per_step < 1:
            raise ValueError(f"trace_rows_per_step must be >= 1, got {trace_rows_per_step}")
        self._cfg[K.CFG_TRACE_ROOM] = trace_rows_per_step
        self.trace_on = np.broadcast_to(np.asarray(trace, np.bool_), (worlds,)).copy()
        # trace rows, row-major (a row is written at once); grown by the backends as they step
        self._tri, self._trf = _trace_buffers(TRACE_MIN_ROWS)
        self._tr_n = np.zeros(1, np.int64)
        self._stats = np.zeros((worlds, K.N_STATS), np.int64)
        self._err = np.zeros(K.N_ERR, np.int64)
        if threads is not None and threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        # one thread unless asked: on this project's 2-core machines a second thread stepping half the
        # batch gained little (docs/benchmarks/history.md, "Threads")
        self.threads = threads or 1
        self._ext_codes = np.zeros(0, np.int8)  # crisp value codes of this step's external rows (lanes)
        self.kernel_notice: str | None = None  # why a requested compiled kernel is not used
        # kernel="compiled" with background_compile: the compile of a kernel not yet cached, running in a
        # child process while this engine steps on the counting kernel (step() takes it over when ready)
        self.background: compile_background.BackgroundCompile | None = None
        self._next_poll = 0.0
        # bumped whenever an array the kernel steps is replaced (grown, handed over, another backend):
        # a caller holding fused_binding()'s arrays binds them again when it changes
        self.layout_version = 0
        self._state: CountingState | LaneState = self._choose_backend(kernel, background_compile)
        self._ext: list[tuple[np.ndarray, ...]] = []  # chunks of (atoms, lower, upper, world, static)
        self._settable = np.zeros(0, np.bool_)
        self._n_settable = 0
        self._ext_count = 0
        self._n_grounded = 0
        self._table: GroundingTable | None = None
        self._kt: KernelTables | None = None  # the groundings as the kernels read them (kernel_tables.py)
        self._agg: AggregateTables | None = None
        self._sync()
        release_freed_memory(self.vocab.n_atoms)  # a big build's temporaries: back to the OS

    # ---- building ----

    @property
    def n_facts(self) -> int:
        return self.graph.n_facts + len(self.program.facts)

    def fact(self, i: int) -> Fact:
        """Fact i in source order: graph facts 0..g-1, then program facts."""
        g = self.graph.n_facts
        return self.graph.fact(i) if i < g else self.program.facts[i - g]

    @property
    def facts(self) -> list[Fact]:
        """Every fact as an object, in source order (one object per graph fact: small graphs only)."""
        return [*self.graph.facts, *self.program.facts]

    def _fact_tables(self) -> None:
        gr = self.graph
        g = gr.n_facts
        # (atom, start, end, static) per fact: int32 (atom ids and times up to MAX_TIME fit), 16 B a fact
        self._fact_i = np.zeros((g + len(self.program.facts), 4), np.int32)
        if self.program.facts:
            self._fact_f = np.zeros((len(self._fact_i), 2), np.float64)
            self._fact_f[:g] = gr.fact_bounds
        else:  # graph facts only: the graph's bound column is the kernel's (no copy of a million rows)
            self._fact_f = np.ascontiguousarray(gr.fact_bounds, np.float64)
        if g:  # graph nodes are the vocabulary's first nodes (ordered_nodes), so node ids carry over
            labels = np.asarray([self.vocab.label(p, n) for p, n in zip(gr.labels, gr.label_arity)], np.int64)
            self._fact_i[:g, 0] = self.vocab.atoms(labels[gr.fact_label], gr.fact_args[:, 0], gr.fact_args[:, 1])
            # a GraphML fact is static at t = 0 (window 0..0, left zero); only fact tables carry columns
            if gr.fact_window is not None:
                self._fact_i[:g, 1:3] = gr.fact_window
            self._fact_i[:g, 3] = gr.statics if gr.fact_static is not None else 1
        for i, f in enumerate(self.program.facts, start=g):
            lit = f.literal
            aid = self.vocab.atom_by_name(lit.pred, tuple(a.name for a in lit.args))
            self._fact_i[i] = (aid, f.start, f.end, int(f.static))
            self._fact_f[i] = effective_bound(lit.lower, lit.upper, lit.negated)
        self.grounder.add_settable_many(self._fact_i[:, 0])
        self._fact_v = crisp_codes(self._fact_f[:, 0], self._fact_f[:, 1])
        # latest-ending first, so that each step stops at the first fact whose window has passed
        ends = self._fact_i[:, 2]
        if len(ends) and (ends == ends[0]).all():  # one window end (every GraphML fact): source order
            self._fact_order = np.arange(len(ends), dtype=np.int32)
        else:
            self._fact_order = np.argsort(-ends, kind="stable").astype(np.int32)

    def _rule_tables(self) -> None:
        n = len(self.rules)
        self._rule_i = np.zeros((n, K.N_RULE_COLUMNS), np.int64)
        self._rule_f = np.zeros((n, 2), np.float64)
        for i, r in enumerate(self.rules):
            mode = r.mode or self.program.mode
            self._rule_i[i] = (UPDATE_MODES.index(mode), r.delay, int(r.immediate), int(r.set_static))
            self._rule_f[i] = rule_head_bound(r)
        self._rule_v = crisp_codes(self._rule_f[:, 0], self._rule_f[:, 1])

    def _choose_backend(self, kernel: str, background_compile: bool) -> CountingState | LaneState:
        """The counting kernel serves every program; the lanes kernel serves crisp ones (every rule head
        and fact sets [0,0], [1,1] or [0,1]) and is faster for large batches. kernel="compiled" on a
        program not yet cached compiles at the first step, or with `background_compile` in a child
        process while the engine starts on the counting kernel."""
        if kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")
        not_crisp = self._not_crisp()
        aggregated = next((r for r in self.rules if r.aggregated), None)
        if aggregated is not None:  # evaluated per head grounding: the counting kernel only
            if kernel == "lanes":
                raise ValueError(f"kernel='lanes' cannot run {aggregated.described}: quantifiers and annotation "
                                 "functions need the counting kernel (kernel='counting' or 'auto')")
            if kernel == "compiled":
                self.kernel_notice = (f"kernel 'compiled' not used: {aggregated.described} has a quantifier or "
                                      "an annotation function; running on the counting kernel")
                log.warning(self.kernel_notice)
            return CountingState(self)
        if kernel == "lanes" and not_crisp:
            raise ValueError(f"kernel='lanes' needs a crisp program (bounds [0,0], [1,1] or [0,1] only): "
                             f"{not_crisp}")
        if kernel == "lanes" or (kernel == "auto" and not not_crisp and self.n_worlds >= LANES_MIN_WORLDS):
            from .backend_lanes import LaneState  # imported for crisp batches only: its 28 kernels' set-up
            return LaneState(self, self.threads)
        if kernel in ("compiled", "auto"):  # auto: only a program the compile cache already holds
            uncached = "skip" if kernel == "auto" else "build" if background_compile else "compile"
            state, self.kernel_notice, to_build = compiled_backend(self, self.program, uncached)
            if state is not None:
                return state
            if to_build is not None:
                self._start_background_compile(to_build)
        return CountingState(self)

    def _start_background_compile(self, entry: CacheEntry) -> None:
        try:
            self.background, new = compile_background.start(self.program, entry)
        except OSError as e:  # an unwritable cache, no process to spare: the run goes on regardless
            self.kernel_notice = (f"kernel 'compiled' not used: cannot start its background compile "
                                  f"({e.strerror or e}: {e.filename or entry.dir}); running on the counting kernel")
            log.warning(self.kernel_notice)
            return
        if new:  # engines of one process share a compile of one kernel: said once
            log.info(f"the compiled kernel is being built in the background (pid {self.background.pid}, a minute "
                     "or more); the run starts on the counting kernel and switches when it is ready")

    def _poll_background(self) -> None:
        """Between two steps: once the background compile has finished, go on with the compiled kernel
        (the counting kernel's state, stepped by the kernel generated from it: the run is the same)."""
        now = time.monotonic()
        if now < self._next_poll:
            return
        self._next_poll = now + BACKGROUND_POLL_S
        job = self.background
        assert job is not None
        status = job.poll()
        if status == "running":
            return
        self.background = None
        if status == "ready" and self.kernel == "counting":
            self._state = CompiledState.taking_over(self._state, job.entry)
            self.layout_version += 1  # a fused caller (envs/declared/fused.py) sees another kernel and steps it apart
            log.info(f"the compiled kernel is ready ({job.describe()}); switched to it at t={self.t}")
        elif status == "failed":
            self.kernel_notice = (f"kernel 'compiled' not used: the background compile failed ({job.why}); "
                                  "going on with the counting kernel")
            log.warning(self.kernel_notice)

    def wait_for_compile(self, timeout: float | None = None) -> str | None:
        """Block until the background compile ends (tests, benchmarks); the next step takes it over.
        Its status, or None when there is none."""
        if self.background is None:
            return None
        self._next_poll = 0.0
        return self.background.wait(timeout)

    def _not_crisp(self) -> str | None:
        """What makes the program not crisp (a rule head or fact and its bound), or None."""
        for i in np.flatnonzero(self._rule_v < 0):
            r = self.rules[i]
            lo, up = self._rule_f[i]
            return f"{r.described} sets [{lo:g},{up:g}]"
        for i in np.flatnonzero(self._fact_v < 0):
            f = self.fact(int(i))
            lo, up = self._fact_f[i]
            return f"{f.described} sets [{lo:g},{up:g}]"
        return None

    @property
    def kernel(self) -> str:
        """The kernel stepping this engine: "counting", "lanes" or "compiled"."""
        return self._state.name

    @property
    def lower(self) -> np.ndarray:
        """Lower bounds, float64 [worlds, atoms] (read-only use: the counting kernel's own array, which
        step() writes; the lanes kernel gives a copy read off its planes)."""
        return self._state.lower

    @property
    def upper(self) -> np.ndarray:
        return self._state.upper

    @property
    def static(self) -> np.ndarray:
        return self._state.static

    def _rule_kinds(self) -> np.ndarray:
        """Per rule, the kernel's kind index: immediate, delayed (Δt > 0) or ordinary Δt = 0."""
        ri = self._rule_i
        kinds = np.where(ri[:, K.RULE_IMMEDIATE] == 1, K.KIND_IMMEDIATE,
                         np.where(ri[:, K.RULE_DELAY] > 0, K.KIND_DELAYED, K.KIND_ORDINARY)).astype(np.int32)
        kinds[aggregated_rules(self.rules)] = K.KIND_AGGREGATE  # fired per head group, not per grounding
        return kinds

    def _sync(self) -> None:
        """Ground any new settable atoms and grow the per-world state to the vocabulary and groundings."""
        g = self.grounder
        if not g.has_pending and self.vocab.n_atoms == self._state.n_atoms \
                and g.n_groundings == self._n_grounded and g.n_settable == self._n_settable:
            return  # the usual case at every step: nothing was interned or made settable since
        if self.cache_grounding and self.t == 0:
            grounding_cache.close(g)
        else:
            g.close()
        n_atoms = self.vocab.n_atoms
        if len(self._settable) != n_atoms or g.n_settable != self._n_settable:
            self._settable = g.settable_mask(n_atoms)
            self._n_settable = g.n_settable
            self.layout_version += 1
        n_inst = g.n_groundings
        if n_inst == self._n_grounded and n_atoms == self._state.n_atoms and self._kt is not None:
            return
        kt = g.kernel_tables(self._rule_kinds(), self._fact_i[:, 0])
        slots = {name: i for i, (name, _) in enumerate(self._user_functions)}
        self._kt, self._agg = kt, aggregate_tables(g, self.rules, kt.inst, slots)
        self._state.grow(n_atoms, self._kt, self._agg)
        self._n_grounded = n_inst
        self._table = None

    def _grow_trace(self, need: int) -> None:
        cap = max(need, 2 * self._tri.shape[0], TRACE_MIN_ROWS)
        n = int(self._tr_n[0])
        tri, trf = _trace_buffers(cap)
        tri[:n] = self._tri[:n]
        trf[:n] = self._trf[:n]
        self._tri, self._trf = tri, trf
        self.layout_version += 1

    def _to_counting(self) -> None:
        """Go on with the counting kernel (a bound the lanes kernel cannot hold arrived)."""
        lower, upper, static, last_cause, pending = self._state.export()
        state = CountingState(self)
        assert self._kt is not None and self._agg is not None  # built by _sync before the lanes kernel stepped
        state.adopt(lower, upper, static, last_cause, pending, self._kt, self._agg)
        self._state = state
        self.layout_version += 1

    # ---- per-world snapshots (episode resets in a batch) ----

    def snapshot(self) -> dict[str, object]:
        """A copy of every world's state before step self.t, for restore()."""
        return {"t": self.t, "kernel": self.kernel, "layout": self._layout(), **self._state.snapshot()}

    def _layout(self) -> str:
        """The state's layout: the compiled backend keeps the counting backend's (a snapshot of one
        restores into the other, as after a switch to the compiled kernel)."""
        return "lanes" if self.kernel == "lanes" else "counting"

    def restore(self, snap: dict[str, object], worlds: np.ndarray, source: np.ndarray | None = None) -> None:
        """Put `worlds` (indices or a bool mask) back into their state in `snap`. Their next step behaves
        as the snapshot's next step did: firings scheduled then are shifted to the current clock. (Program
        facts with time windows follow the engine's one clock; per-world restarts see them by that clock.)
        `source`: world worlds[i] takes the state of snap's world source[i] instead
        of its own, e.g. one of several start states prepared in a batch (a declared vector env's resets)."""
        worlds = np.flatnonzero(worlds) if np.asarray(worlds).dtype == np.bool_ else np.asarray(worlds)
        if worlds.size == 0:
            return
        if snap["layout"] != self._layout():
            raise RuntimeError(f"this snapshot was taken by the {snap['kernel']} kernel, but the engine now "
                               f"runs the {self.kernel} kernel (a non-crisp external fact arrived); take a "
                               "new snapshot")
        shift = self.t - int(snap["t"])
        if source is None:
            self._state.restore(snap, worlds.astype(np.int64), shift)
            return
        source = np.asarray(source, np.int64)
        if source.shape != worlds.shape or source.min() < 0 or source.max() >= self.n_worlds:
            raise ValueError(f"source must give one world of the snapshot (0..{self.n_worlds - 1}) per "
                             f"restored world, got {source.tolist()}")
        self._state.restore(snap, worlds.astype(np.int64), shift, source)

    def set_bounds(self, atoms: np.ndarray, lower: np.ndarray, upper: np.ndarray, static: np.ndarray,
                   world: int = 0) -> None:
        """Put `world`'s atoms at these bounds before the next step, as if set then (no trace row, no cause):
        an interpretation carried over from another engine, e.g. a reasoning continued with more rules
        (tracelab.pyreason's reason(again=True)). The atoms become settable, and the groundings that read
        them are recounted (the counting kernel goes on)."""
        atoms = np.asarray(atoms, np.int64)
        self.grounder.add_settable_many(atoms)
        self._sync()
        if self.kernel == "lanes":
            self._to_counting()
        self._state.set_bounds(world, atoms, np.asarray(lower, np.float64), np.asarray(upper, np.float64),
                               np.asarray(static, np.bool_))

    # ---- atoms ----

    def atom(self, pred: str, *args: str) -> int:
        """The id of pred(args), interned on demand."""
        # interning only: the per-world arrays grow at the next step (or sync()), so that interning
        # thousands of atoms one by one stays linear
        return self.vocab.atom_by_name(pred, tuple(args))

    def atom_text(self, aid: int) -> str:
        return self.vocab.atom_text(aid)

    def known_atom(self, pred: str, *args: str) -> int | None:
        """The id of pred(args) if the engine knows it, else None (never interns: a reader's question does
        not grow the engine)."""
        label = self.vocab.label_ids.get(pred)
        nodes = [self.vocab.node_ids.get(a) for a in args]
        if label is None or any(n is None for n in nodes):
            return None
        return self.vocab.find(label, tuple(nodes))

    def _lookup(self, text: str) -> int | None:
        lit = parse_literal(text)
        return self.known_atom(lit.pred, *(a.name for a in lit.args))

    # ---- facts in, steps, values out ----

    def add_fact(self, atom: int, lower: float = 1.0, upper: float = 1.0, world: int | None = None,
                 static: bool = False) -> None:
        """An external fact, applied at pass 0 of the next step (in `world`, or in every world)."""
        if world is not None and not 0 <= world < self.n_worlds:
            raise ValueError(f"world {world} out of range 0..{self.n_worlds - 1}")
        self.add_facts(np.array([atom]), lower, upper, None if world is None else np.array([world]), static)

    def add_facts(self, atoms: np.ndarray, lower: np.ndarray | float, upper: np.ndarray | float,
                  worlds: np.ndarray | None = None, static: bool = False) -> None:
        """External facts, one per element (world -1 or None: every world), for the next step."""
        atoms = np.asarray(atoms, np.int64).ravel()
        lower = np.broadcast_to(np.asarray(lower, np.float64), atoms.shape)
        upper = np.broadcast_to(np.asarray(upper, np.float64), atoms.shape)
        worlds = np.full(atoms.shape, -1, np.int64) if worlds is None else \
            np.broadcast_to(np.asarray(worlds, np.int64), atoms.shape)
        bad = ~((lower >= 0) & (lower <= upper) & (upper <= 1))
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"bound [{lower[i]},{upper[i]}] of {self.atom_text(int(atoms[i]))} is not "
                             "inside [0,1] with lower <= upper")
        if atoms.size and (atoms.min() < 0 or atoms.max() >= self.vocab.n_atoms):
            raise ValueError(f"atom ids must lie in 0..{self.vocab.n_atoms - 1}")
        if (worlds >= self.n_worlds).any():
            raise ValueError(f"world ids must lie in 0..{self.n_worlds - 1} (or -1 for every world)")
        known = self._settable[atoms[atoms < len(self._settable)]]
        if known.size < atoms.size or not known.all():
            self.grounder.add_settable_many(atoms)
        self._ext.append((atoms, lower, upper, worlds, np.full(atoms.shape, int(static), np.int64)))

    def _external_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w = self.n_worlds
        if not self._ext:
            return np.zeros(w + 1, np.int64), np.zeros((0, 3), np.int64), np.zeros((0, 2))
        atoms, lower, upper, world, static = (np.concatenate(c) for c in zip(*self._ext))
        self._ext = []
        ids = self._ext_count + np.arange(len(atoms), dtype=np.int64)
        self._ext_count += len(atoms)
        # a fact for every world is repeated per world; rows are grouped by world for the kernel
        everywhere = world < 0
        if everywhere.any():
            rep = np.repeat(np.flatnonzero(everywhere), w)
            rep_world = np.tile(np.arange(w), int(everywhere.sum()))
            keep = np.flatnonzero(~everywhere)
            idx = np.concatenate([keep, rep])
            world = np.concatenate([world[keep], rep_world])
        else:
            idx = np.arange(len(atoms))
        order = np.argsort(world, kind="stable")
        idx, world = idx[order], world[order]
        ext_i = np.column_stack([atoms[idx], static[idx], ids[idx]])
        ext_f = np.column_stack([lower[idx], upper[idx]])
        ptr = np.zeros(w + 1, np.int64)
        np.add.at(ptr, world + 1, 1)
        return np.cumsum(ptr), ext_i, ext_f

    def step(self, external: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> None:
        """Compute timestep self.t in every world, then advance t.
        `external` is a fast path for simulators that build their fact rows themselves: (ptr int64[W+1],
        rows int64[R,3] (atom, static, id), bounds float64[R,2]), rows grouped by world, atoms settable
        (given once to add_facts) and ids from `next_external_id()` on. It replaces add_fact(s)."""
        if self.background is not None:
            self._poll_background()
        self._sync()
        if external is None:
            ext_ptr, ext_i, ext_f = self._external_arrays()
        else:
            if self._ext:
                raise RuntimeError("step(external=...) with facts queued by add_fact(s): use one or the other")
            ext_ptr, ext_i, ext_f = external  # the kernel refuses atoms nothing can set
            n = int(ext_ptr[-1])
        if self.kernel == "lanes":
            self._ext_codes = crisp_codes(ext_f[:, 0], ext_f[:, 1])
            if (self._ext_codes < 0).any():
                self._to_counting()
        self._cfg[K.CFG_T] = self.t
        status = self._state.step(ext_ptr, ext_i, ext_f)
        if status != K.STATUS_OK:
            self._raise(status)
        if external is not None:
            self._ext_count += n
        self.t += 1

    # ---- a caller's own compiled step (tracelab/envs/declared/fused.py, vector_fused.py) ----

    def fused_binding(self) -> K.StepState | None:
        """For a caller that runs the counting kernel inside its own compiled call (it sets cfg[CFG_T], then
        calls kernel.step_worlds): after sync(), the kernel's step state (CountingState.step_state); None on
        another kernel. Valid
        while layout_version stays the same; such a step is begun with prepare_fused_step() and ended with
        finish_fused_step()."""
        self._sync()
        if self._state.name != "counting":
            return None
        return self._state.step_state()

    def prepare_fused_step(self) -> int:
        """Before a fused step: ground what is new (as step() does); returns layout_version, which the
        caller compares with its binding's."""
        if self._ext:  # as step(external=...)
            raise RuntimeError("step(external=...) with facts queued by add_fact(s): use one or the other")
        if self.background is not None:  # as step(): take over a finished background compile
            self._poll_background()
        self._sync()
        return self.layout_version

    def finish_fused_step(self, status: int, w_first: int, ext_ptr: np.ndarray, ext_i: np.ndarray,
                          ext_f: np.ndarray) -> None:
        """After a fused step's kernel call returned (status, w_first) for the external rows (ext_ptr and
        the row buffers, rows ext_ptr[-1] of them used, as in step()): go on as step() would (grow a
        buffer, user functions; raise on an error), then advance t."""
        n = int(ext_ptr[-1])
        if status != K.STATUS_OK:
            status = self._state.finish(status, w_first, ext_ptr, ext_i[:n], ext_f[:n])
            if status != K.STATUS_OK:
                self._raise(status)
        self._ext_count += n
        self.t += 1

    def next_external_id(self) -> int:
        """The id the next external fact will get (trace rows name external facts by this id)."""
        return self._ext_count

    def run(self, steps: int) -> None:
        for _ in range(steps):
            self.step()

    def bound(self, atom: int, world: int = 0) -> tuple[float, float]:
        if atom >= self._state.n_atoms:
            return (0.0, 1.0)
        return self._state.bound(atom, world)

    def is_true(self, atoms: np.ndarray) -> np.ndarray:
        """bool [worlds, len(atoms)]: where each atom is [1,1] (a simulator's read-back, fast for both
        kernels; atoms must exist, see sync())."""
        return self._state.truth(np.asarray(atoms, np.int64), 1.0)

    def is_false(self, atoms: np.ndarray) -> np.ndarray:
        """bool [worlds, len(atoms)]: where each atom is [0,0]."""
        return self._state.truth(np.asarray(atoms, np.int64), 0.0)

    def query(self, text: str, world: int = 0) -> tuple[float, float]:
        """The bound of an atom given as text, e.g. "atLoc(red-agent-1,16)"; [0,1] if never set."""
        aid = self._lookup(text)
        return (0.0, 1.0) if aid is None else self.bound(aid, world)

    def match(self, pattern: str, world: int = 0) -> list[tuple[dict[str, str], tuple[float, float]]]:
        """The atoms a literal with variables holds of, e.g. "infected(X)" or "link(a,Y):[0.5,1]"
        (a missing annotation means [1,1], as in rules; `~` tests the complement): one (bindings,
        bound) per atom, in atom order. Only atoms the engine knows are candidates."""
        lit = parse_literal(pattern)
        label = self.vocab.label_ids.get(lit.pred)
        if label is None or self.vocab.label_arity[label] != len(lit.args):
            return []
        n = self._state.n_atoms
        cand = np.flatnonzero(self.vocab.atom_label[:n] == label)
        cols = (self.vocab.atom_arg0[:n], self.vocab.atom_arg1[:n])
        first_pos: dict[str, int] = {}
        for pos, term in enumerate(lit.args):
            vals = cols[pos][cand]
            if not term.is_var:
                node = self.vocab.node_ids.get(term.name)
                cand = cand[vals == node] if node is not None else cand[:0]
            elif term.name in first_pos:  # p(X,X): both arguments equal
                cand = cand[vals == cols[first_pos[term.name]][cand]]
            else:
                first_pos[term.name] = pos
        lo, up = self.lower[world][cand], self.upper[world][cand]
        if lit.negated:
            lo, up = 1.0 - up, 1.0 - lo
        hold = (lo >= lit.lower - EPS) & (up <= lit.upper + EPS)
        out = []
        for a in cand[hold].tolist():
            binding = {v: self.vocab.nodes[int(cols[p][a])] for v, p in first_pos.items()}
            out.append((binding, (float(self.lower[world][a]), float(self.upper[world][a]))))
        return out

    def interpretation(self, world: int = 0) -> dict[str, tuple[float, float]]:
        """Every atom whose bound is not [0,1], by its text."""
        lo, up = self.lower[world], self.upper[world]
        known = np.flatnonzero((lo != 0.0) | (up != 1.0))
        return {self.vocab.atom_text(int(a)): (float(lo[a]), float(up[a])) for a in known}

    # ---- trace, vocabulary, groundings, stats ----

    @property
    def trace_rows_waiting(self) -> int:
        """Change rows in the trace buffer that take_trace() has not handed out yet."""
        return int(self._tr_n[0])

    def take_trace(self, t_start: np.ndarray | None = None,
                   episode: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """The change rows since the last call, as columns (docs/engine-api.md); the buffer is cleared.
        With `t_start` and `episode` (int64 [worlds] each; a simulator's episode clock) a row's `t` is
        counted from t_start[its world] and a last column `world_episode` holds episode[its world]."""
        n = int(self._tr_n[0])
        local = t_start is not None
        if local and n < TRACE_HANDOVER_ROWS:  # the usual step: new columns, localised, in one call
            self._tr_n[0] = 0
            ints, kind, nsrc, floats, ep = take_local_columns(self._tri, self._trf, n, t_start, episode)
            got = {**dict(zip(INT32_COLUMNS, ints)), **dict(zip(_TRACE_FLOAT_NAMES, floats)),
                   "cause_kind": kind, "n_sources": nsrc, "world_episode": ep}
            return {name: got[name] for name in TRACE_LOCAL_COLUMNS}
        ints, floats = self._tri.T[:, :n], self._trf.T[:, :n]  # the buffers' columns, contiguous blocks
        if n >= TRACE_HANDOVER_ROWS:  # a big step: its columns are handed over, the engine starts anew
            self._tri, self._trf = _trace_buffers(TRACE_MIN_ROWS)
            self.layout_version += 1
        else:  # one copy per block (the buffers are reused); the columns are its rows
            ints, floats = ints.copy(), floats.copy()
        cols: dict[str, np.ndarray] = {}
        for (name, dtype, as_is), col in zip(_TRACE_INT_OUT, ints):
            cols[name] = col if as_is else col.astype(dtype)
        for name, col in zip(_TRACE_FLOAT_NAMES, floats):
            cols[name] = col
        self._tr_n[0] = 0
        if local:
            world = cols["world"].astype(np.int64)
            cols["t"] = (cols["t"] - t_start[world]).astype(np.int32)
            cols["world_episode"] = episode[world].astype(np.int64)
        return cols

    def vocabulary(self) -> dict[str, object]:
        return self.vocab.arrays()

    @property
    def groundings(self) -> GroundingTable:
        if self._table is None or len(self._table.rule) != self.grounder.n_groundings:
            self._table = self.grounder.table()
        return self._table

    @property
    def stats(self) -> dict[str, np.ndarray]:
        return {name: self._stats[:, i].copy() for i, name in enumerate(STAT_NAMES)}

    def pending(self, world: int = 0) -> list[tuple[int, int]]:
        """Scheduled firings of delayed rules: (due time, grounding id)."""
        return self._state.pending(world)

    def cause_name(self, kind: int, cid: int) -> str:
        """A short name for a trace row's cause: the rule's name, fact:NAME, external, policy:NAME, reset."""
        if kind == K.CAUSE_RULE:
            return self.rules[cid].name
        if kind == K.CAUSE_FACT:
            return f"fact:{self.fact(cid).name}"
        if kind == K.CAUSE_EXTERNAL:
            return "external"
        if kind == K.CAUSE_POLICY:
            return f"policy:{INCONSISTENCY_POLICIES[cid]}"
        return "reset"

    def grounding_text(self, g: int) -> str:
        """A grounding as its variable values, e.g. "X=a, Y=b" ("" for none)."""
        if g < 0:
            return ""
        table = self.groundings
        rule = self.rules[int(table.rule[g])]
        return ", ".join(f"{v}={constant_text(self.vocab.nodes[x])}" for v, x in zip(rule.variables, table.values(g)))

    # ---- errors ----

    def describe_source(self, kind: int, cid: int, grounding: int = -1) -> str:
        if kind == K.CAUSE_FACT:
            return self.fact(cid).described
        if kind == K.CAUSE_EXTERNAL:
            return f"external fact #{cid}"
        if kind == K.CAUSE_RULE:
            r = self.rules[cid]
            if grounding >= 0:
                return f"{r.described} with {self.grounding_text(grounding) or 'no variables'}"
            return r.described
        if kind == K.CAUSE_POLICY:
            return f"inconsistency policy {INCONSISTENCY_POLICIES[cid]}"
        if kind == K.CAUSE_RESET:
            return "the reset at the start of the step"
        return "nothing (the atom was never set)"

    def _raise(self, status: int) -> None:
        e = self._err
        w, t, a = int(e[0]), int(e[1]), int(e[2])
        if status == K.STATUS_INCONSISTENT:
            first = self.describe_source(int(e[5]), int(e[6]), int(e[7]))
            lo, up = self.bound(a, w)
            old = self.describe_source(int(e[3]), int(e[4]))
            where = f"inconsistent bounds for {self.atom_text(a)} at t={t} (world {w})"
            if e[11]:  # the incoming sources disagree among themselves
                last = self.describe_source(int(e[8]), int(e[9]), int(e[10]))
                raise InconsistencyError(
                    f"{where}: {first} and {last} set disjoint bounds in the same pass; the bound before "
                    f"was [{lo:g},{up:g}], from {old}")
            raise InconsistencyError(
                f"{where}: its bound [{lo:g},{up:g}] came from {old}; the incoming bound from {first} is "
                "disjoint from it")
        if status == K.STATUS_TRACE_LIMIT:
            raise RuntimeError(f"internal error: a trace row of world {w} at t={self.t} found no room")
        if status == K.STATUS_NOT_SETTABLE:
            raise ValueError(f"step(external=...) names {self.atom_text(a)}, which no fact or rule can set; "
                             "give such atoms to add_facts once first")
        if status == K.STATUS_IMMEDIATE_LIMIT:
            raise FixpointError(
                f"immediate rules did not settle at t={t} (world {w}) after "
                f"{int(self._cfg[K.CFG_MAX_IMMEDIATE])} applications ({self.atom_text(a)} the last): "
                f"{self._still_changing(w, t, immediate=True)}")
        raise FixpointError(
            f"no fixpoint at t={t} (world {w}) after {int(self._cfg[K.CFG_MAX_PASSES])} passes: "
            f"{self._still_changing(w, t, immediate=False)}")

    def _still_changing(self, w: int, t: int, immediate: bool) -> str:
        """What kept a step from its fixpoint: the atoms changed in its last two passes and by what, read
        from the trace buffer (not taken: take_trace() still returns them), else the rules that can."""
        n = int(self._tr_n[0])
        rows = self._tri[:n]
        mine = rows[(rows[:, 0] == w) & (rows[:, 1] == t)]
        if len(mine):
            last_pass = int(mine[:, 2].max())
            causes: dict[int, list[str]] = {}
            for row in mine[mine[:, 2] >= last_pass - 1]:
                atom, kind, cid, g = int(row[3]), int(row[4]), int(row[5]), int(row[6])
                by = causes.setdefault(atom, [])
                if (text := self.describe_source(kind, cid, g)) not in by:
                    by.append(text)
            shown = [f"{self.atom_text(a)} by {', then '.join(by)}" for a, by in causes.items()]
            more = f" and {len(shown) - 5} more atoms" if len(shown) > 5 else ""
            return (f"still changing in passes {last_pass - 1}-{last_pass}: " + "; ".join(shown[:5]) + more +
                    " (rules, or a policy, that undo each other)")
        if immediate:
            candidates, kind = [i for i, r in enumerate(self.rules) if r.immediate], "immediate rules"
        else:
            candidates = [i for i, r in enumerate(self.rules)
                          if not r.delay and not r.immediate and (r.mode or self.program.mode) == "override"]
            kind = "Δt = 0 rules in override mode"
        if candidates:
            names = [self.describe_source(K.CAUSE_RULE, i) for i in candidates[:8]]
            return (f"atoms keep changing; the {kind}: " + "; ".join(names) +
                    (" ..." if len(candidates) > 8 else "") + " (trace the world to see the atoms)")
        return (f"the policy {self.program.inconsistency} keeps changing atoms (trace the world to see "
                "which)")
