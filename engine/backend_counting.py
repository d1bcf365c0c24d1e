"""Per-world state of the counting kernel (kernel.py): the general backend, for any program and batch.

Every world keeps its own intervals (float [world, atom]), its groundings' unsatisfied-clause counts and
active lists, and its schedule of delayed firings. The Engine (core.py) owns the program tables, the trace
buffer and the statistics; this class owns the state and runs the kernel over it.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from . import annotations
from . import kernel as K
from .backend_api import EngineTables
from .direct_call import DirectCall
from .kernel_tables import AggregateTables, KernelTables
from .program import effective_bound
from .restore_kernel import restore_groundings


class CountingState:
    name = "counting"
    step_kernel = staticmethod(K.step_worlds)  # the compiled backend steps the same state with its own

    def __init__(self, eng: EngineTables) -> None:
        self.eng = eng
        w = eng.n_worlds
        self.lower = np.zeros((w, 0))
        self.upper = np.ones((w, 0))
        self.static = np.zeros((w, 0), np.bool_)
        self.last_cause = np.full((w, 0, 2), -1, np.int32)
        self._unsat = np.zeros((w, 0), np.int8)
        self._act = np.zeros((w, 0), np.int32)
        self._act_pos = np.zeros((w, 0), np.int32)
        self._act_n = np.zeros((w, K.N_KINDS), np.int64)
        self._kind_base = np.zeros(K.N_KINDS, np.int64)
        self._pend = np.zeros((w, 16, 2), np.int32)
        self._pend_f = np.zeros((w, 16, 2), np.float64)  # the bound each scheduled firing sets
        self._pend_n = np.zeros(w, np.int64)
        self._fixed = np.zeros(w, np.bool_)  # StepState.fixed: cleared wherever the state changes outside a step
        self._n_touched = np.zeros(1, np.int64)
        self._changed = np.zeros(1, np.int64)
        self._out = np.zeros(5, np.float64)
        self._n_grounded = 0
        self._stamp = np.zeros(1, np.int64)  # aggregated rules: distinct-atom marks are stamps
        self._req_n = np.zeros(1, np.int64)
        self._scratch(0, 0)
        self._state_version = -1  # the layout_version step_state() was built at
        self._step_call: DirectCall | None = None  # step_kernel over step_state(), past numba's dispatch

    @property
    def n_atoms(self) -> int:
        return self.lower.shape[1]

    def _scratch(self, n_atoms: int, n_inst: int) -> None:
        # grouping scratch, one row per atom touched in a pass (slot_of maps atoms to rows, -1: none)
        self._slot_of = np.full(max(n_atoms, 1), -1, np.int32)
        self._touched = np.zeros(max(n_atoms, 1), np.int32)
        self._si = np.zeros((max(n_atoms, 1), K.N_SCRATCH_INT), np.int64)
        self._sf = np.zeros((max(n_atoms, 1), K.N_SCRATCH_FLOAT), np.float64)
        # immediate-phase candidates: a heap of rank * 2^31 + grounding, and membership flags
        self._heap = np.zeros(max(n_inst, 1), np.int64)
        self._in_heap = np.zeros(max(n_inst, 1), np.bool_)
        # aggregated rules: atom marks, the atoms one head group feeds its function, user-function requests
        cap = self.agg.gather_cap if n_inst or n_atoms else 1
        self._mark = np.zeros((2, max(n_atoms, cap, 1)), np.int64)  # stamps by atom; a clause's candidates
        self._g = np.zeros((3, cap), np.float64)
        req = self.agg.request_cap if n_inst or n_atoms else 1
        self._req_i = np.zeros((req, 2), np.int64)
        self._req_f = np.zeros((req, 2), np.float64)
        self._req_ptr = np.zeros(req + 1, np.int64)
        self._req_atoms = np.zeros((3, self.agg.user_gather_cap if n_inst or n_atoms else 1))

    def grow(self, n_atoms: int, kt: KernelTables, agg: AggregateTables) -> None:
        """Room for n_atoms atoms and every grounding of kt (new atoms start at [0,1], new groundings
        are counted from the current intervals); agg: the aggregated rules' head groups."""
        w = self.eng.n_worlds
        grow = n_atoms - self.n_atoms
        if grow > 0:
            self.lower = np.concatenate([self.lower, np.zeros((w, grow))], axis=1)
            self.upper = np.concatenate([self.upper, np.ones((w, grow))], axis=1)
            self.static = np.concatenate([self.static, np.zeros((w, grow), np.bool_)], axis=1)
            self.last_cause = np.concatenate([self.last_cause, np.full((w, grow, 2), -1, np.int32)], axis=1)
        self.kt, self.agg = kt, agg
        n_inst = len(kt.inst)
        first = self._n_grounded
        if n_inst > first:
            # each kind's active list has room for every grounding of that kind
            counts = np.bincount(kt.inst[:, K.INST_KIND], minlength=K.N_KINDS)
            kind_base = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
            act = np.zeros((w, n_inst), np.int32)
            K.relayout_active(self._act, self._kind_base, act, kind_base, self._act_n)
            self._act, self._kind_base = act, kind_base
            self._unsat = np.concatenate([self._unsat, np.zeros((w, n_inst - first), np.int8)], axis=1)
            self._act_pos = np.concatenate([self._act_pos, np.full((w, n_inst - first), -1, np.int32)], axis=1)
            K.recount_groundings(first, self.lower, self.upper, kt.b_ptr, kt.b_atom, kt.b_flags,
                                 kt.b_bnd, kt.inst, self._kind_base, self._unsat, self._act, self._act_n,
                                 self._act_pos)
        self._n_grounded = n_inst
        self._fixed[:] = False  # new groundings, counted from the intervals: any may apply
        self._scratch(n_atoms, n_inst)
        self.eng.layout_version += 1  # step_state() changed

    def _agg_args(self) -> tuple[np.ndarray, ...]:
        agg = self.agg
        return (agg.hg_i, agg.hg_ptr, agg.je_g, agg.je_body, agg.ag_rule, agg.ag_cf, agg.ag_cn,
                agg.ag_q, agg.ag_qv, self._mark, self._stamp, self._g[0], self._g[1], self._g[2])

    def _user_functions(self, w: int) -> None:
        """The kernel waits on queued head groups with user annotation functions: compute their bounds."""
        agg, eng = self.agg, self.eng
        K.agg_gather_requests(w, self.lower, self.upper, self._unsat, *self._agg_args(), self._req_i,
                              self._req_n, self._req_atoms, self._req_ptr)
        ptr, atoms = self._req_ptr, self._req_atoms
        for i in range(int(self._req_n[0])):
            ai = int(agg.hg_i[self._req_i[i, 0], 0])
            rule = eng.rules[int(agg.ag_rule[ai, K.AR_RULE])]
            name, fn = eng._user_functions[int(agg.ag_rule[ai, K.AR_USER])]
            a, b = ptr[i], ptr[i + 1]
            lo, up = annotations.call_user(name, fn, rule.name, atoms[0, a:b], atoms[1, a:b], atoms[2, a:b])
            self._req_f[i] = effective_bound(lo, up, rule.head.negated)

    def step_state(self) -> K.StepState:
        """The kernel's step state over the current buffers: the one place that gathers them (built once
        per Engine.layout_version; a caller running the kernel in its own compiled call holds it while
        layout_version stays the same, see Engine.fused_binding)."""
        eng = self.eng
        if self._state_version == eng.layout_version:
            return self._step_state
        kt, agg = self.kt, self.agg
        self._step_state = K.StepState(
            cfg=eng._cfg, rule_i=eng._rule_i, rule_f=eng._rule_f, inst=kt.inst, kind_base=self._kind_base,
            wc_ptr=kt.wc_ptr, wc_bnd=kt.wc_bnd, wc_flags=kt.wc_flags, wc_gptr=kt.wc_gptr, wg=kt.wg,
            ih_ptr=kt.ih_ptr, ih_inst=kt.ih_inst, fact_i=eng._fact_i, fact_f=eng._fact_f,
            fact_order=eng._fact_order, settable=eng._settable, lo=self.lower, up=self.upper, static=self.static,
            last_cause=self.last_cause, unsat=self._unsat, act=self._act, act_n=self._act_n, act_pos=self._act_pos,
            pend=self._pend, pend_n=self._pend_n, trace_on=eng.trace_on, tri=eng._tri, trf=eng._trf,
            tr_n=eng._tr_n, stats=eng._stats, err=eng._err, slot_of=self._slot_of, touched=self._touched,
            n_touched=self._n_touched, si=self._si, sf=self._sf, out=self._out, heap=self._heap,
            in_heap=self._in_heap, changed=self._changed, hg_i=agg.hg_i, hg_ptr=agg.hg_ptr, je_g=agg.je_g,
            je_body=agg.je_body, ag_rule=agg.ag_rule, ag_cf=agg.ag_cf, ag_cn=agg.ag_cn, ag_q=agg.ag_q,
            ag_qv=agg.ag_qv, mark=self._mark, stamp=self._stamp, g_l=self._g[0], g_u=self._g[1], g_w=self._g[2],
            req_i=self._req_i, req_f=self._req_f, req_n=self._req_n, pend_f=self._pend_f, fixed=self._fixed)
        self._state_version = eng.layout_version
        return self._step_state

    def step(self, ext_ptr: np.ndarray, ext_i: np.ndarray, ext_f: np.ndarray) -> int:
        """One timestep of every world; returns the kernel's status (buffers grown as needed)."""
        return self.finish(None, 0, ext_ptr, ext_i, ext_f)

    def finish(self, status: int | None, w_first: int, ext_ptr: np.ndarray, ext_i: np.ndarray,
               ext_f: np.ndarray) -> int:
        """Go on with a step whose kernel call returned (status, w_first) (None: not called yet) until it
        is done or fails, as step() does: grow a buffer or compute user functions and call the kernel
        again from world w_first. Returns the final status."""
        while True:
            if status is not None and not self._serve(status, w_first):
                break
            status, w_first = self._kernel_call()(w_first, ext_ptr, ext_i, ext_f)
        if status != K.STATUS_OK:
            self._reset_after_error()
        return status

    def _kernel_call(self) -> DirectCall:
        """step_kernel bound to the current step state (new when the layout or the kernel changes)."""
        state, call = self.step_state(), self._step_call
        if call is None or call.record is not state or call.dispatcher is not self.step_kernel:
            call = self._step_call = DirectCall(self.step_kernel, state)
        return call

    def _serve(self, status: int, w_first: int) -> bool:
        """What a kernel call that paused with `status` at world w_first needs before it goes on; False
        when it does not go on (done, or an error)."""
        eng = self.eng
        if status == K.STATUS_TRACE_ROOM:  # grow the trace buffer, go on in that world
            eng._grow_trace(int(eng._tr_n[0]) + int(eng._cfg[K.CFG_TRACE_NEED]))
        elif status == K.STATUS_PEND_ROOM:  # grow the schedule, then that world schedules its firings
            self._grow_pending(int(self._pend_n[w_first]) + int(self._act_n[w_first, K.KIND_DELAYED])
                               + len(self.agg.hg_i))
            eng._cfg[K.CFG_RESUME_SCHEDULE] = K.RESUME_PEND_ROOM
        elif status == K.STATUS_USER_FN:  # Python computes the user functions, the kernel goes on
            try:
                self._user_functions(w_first)
            except Exception:
                self._reset_after_error()
                raise
        else:
            return False
        return True

    def _reset_after_error(self) -> None:
        """An error may leave candidates, scratch rows and requests behind."""
        self._in_heap[:] = False
        self._slot_of[:] = -1
        self._n_touched[0] = 0
        self._req_n[0] = 0
        self.eng._cfg[K.CFG_RESUME_SCHEDULE] = 0
        self.eng._cfg[K.CFG_RESUME_PHASE] = K.PHASE_FRESH

    def _grow_pending(self, need: int) -> None:
        cap = max(need, 2 * self._pend.shape[1], 16)
        pend = np.zeros((self.eng.n_worlds, cap, 2), np.int32)
        pend[:, :self._pend.shape[1]] = self._pend
        pend_f = np.zeros((self.eng.n_worlds, cap, 2), np.float64)
        pend_f[:, :self._pend_f.shape[1]] = self._pend_f
        self._pend, self._pend_f = pend, pend_f
        self.eng.layout_version += 1

    def snapshot(self) -> dict[str, Any]:
        return {"lower": self.lower.copy(), "upper": self.upper.copy(), "static": self.static.copy(),
                "last_cause": self.last_cause.copy(), "unsat": self._unsat.copy(), "act": self._act.copy(),
                "act_pos": self._act_pos.copy(), "act_n": self._act_n.copy(), "pend": self._pend.copy(),
                "pend_f": self._pend_f.copy(), "pend_n": self._pend_n.copy()}

    def set_bounds(self, world: int, atoms: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                   static: np.ndarray) -> None:
        """World `world`'s atoms take these bounds (no cause); its groundings are recounted from them."""
        self.lower[world, atoms] = lower
        self.upper[world, atoms] = upper
        self.static[world, atoms] = static
        self.last_cause[world, atoms] = -1
        self._fixed[world] = False
        kt = self.kt
        K.recount_worlds(np.array([world], np.int64), self.lower, self.upper, kt.b_ptr, kt.b_atom, kt.b_flags,
                         kt.b_bnd, kt.inst, self._kind_base, self._unsat, self._act, self._act_n, self._act_pos)

    def restore(self, snap: dict[str, Any], indices: np.ndarray, shift: int, sources: np.ndarray | None = None
                ) -> None:
        """Worlds `indices` take their state from snap's worlds `sources` (default: the same worlds); their
        scheduled firings move `shift` steps later."""
        sources = indices if sources is None else sources
        self._fixed[indices] = False  # a snapshot's state may not be a fixpoint (one taken before any step)
        worlds: slice | np.ndarray = indices
        src: slice | np.ndarray = sources
        if indices.size == 1:  # one world (the usual episode end): basic indexing, no fancy-index copies
            worlds = slice(int(indices[0]), int(indices[0]) + 1)
            src = slice(int(sources[0]), int(sources[0]) + 1)
        n_atoms = snap["lower"].shape[1]
        if n_atoms < self.n_atoms:  # atoms interned since the snapshot start unset
            self.lower[worlds] = 0.0
            self.upper[worlds] = 1.0
            self.static[worlds] = False
            self.last_cause[worlds] = -1
        self.lower[worlds, :n_atoms] = snap["lower"][src]
        self.upper[worlds, :n_atoms] = snap["upper"][src]
        self.static[worlds, :n_atoms] = snap["static"][src]
        self.last_cause[worlds, :n_atoms] = snap["last_cause"][src]
        if snap["unsat"].shape == self._unsat.shape and n_atoms == self.n_atoms:
            restore_groundings(indices, sources, snap["unsat"], snap["act"], snap["act_n"], self._unsat, self._act,
                               self._act_n, self._act_pos, self._kind_base)
        else:  # groundings grew since the snapshot: recount those worlds from their interpretation
            kt = self.kt
            K.recount_worlds(indices, self.lower, self.upper, kt.b_ptr, kt.b_atom, kt.b_flags,
                             kt.b_bnd, kt.inst, self._kind_base, self._unsat, self._act, self._act_n,
                             self._act_pos)
        pend, pend_n = snap["pend"], snap["pend_n"]
        if pend.shape[1] > self._pend.shape[1]:
            self._grow_pending(pend.shape[1])
        self._pend[worlds, :pend.shape[1]] = pend[src]
        self._pend_f[worlds, :pend.shape[1]] = snap["pend_f"][src]
        self._pend[worlds, :, 0] += shift
        self._pend_n[worlds] = pend_n[src]

    def bound(self, atom: int, world: int) -> tuple[float, float]:
        return float(self.lower[world, atom]), float(self.upper[world, atom])

    def truth(self, atoms: np.ndarray, value: float) -> np.ndarray:
        """bool [worlds, atoms]: value 1.0, where each atom is [1,1]; value 0.0, where it is [0,0]."""
        out = np.empty((self.eng.n_worlds, len(atoms)), np.bool_)
        K.gather_truth(self.lower if value == 1.0 else self.upper, atoms, value, out)
        return out

    def pending(self, world: int) -> list[tuple[int, int]]:
        n = int(self._pend_n[world])
        return [(int(d), int(g)) for d, g in self._pend[world, :n]]

    def adopt(self, lower: np.ndarray, upper: np.ndarray, static: np.ndarray, last_cause: np.ndarray,
              pending: list[list[tuple[int, int]]], kt: KernelTables, agg: AggregateTables) -> None:
        """Take over a batch from another backend: intervals [world, atom], schedules per world."""
        self.lower, self.upper = np.ascontiguousarray(lower), np.ascontiguousarray(upper)
        self.static, self.last_cause = np.ascontiguousarray(static), np.ascontiguousarray(last_cause)
        self.grow(self.n_atoms, kt, agg)  # counts every grounding from these intervals
        cap = max((len(p) for p in pending), default=0)
        self._grow_pending(cap)
        for w, entries in enumerate(pending):
            for i, (due, g) in enumerate(entries):  # the lanes kernel serves no aggregated rule
                self._pend[w, i] = (due, g)
                self._pend_f[w, i] = self.eng._rule_f[kt.inst[g, K.INST_RULE]]
            self._pend_n[w] = len(entries)
