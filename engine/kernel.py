"""The compiled step kernel: one call computes one timestep for every world of a batch.

Everything here works on flat integer/float arrays, so one compiled kernel serves every rule program:
a new rule file changes the arrays, never the code (no recompile). All njit code lives in this one
module because numba's disk cache does not notice changes to callees in other modules.

How rules are evaluated: the grounder (grounding.py) enumerates, once, every rule grounding that could
ever fire. Each grounding keeps a count of its body clauses that do not hold (`unsat`); a change of an
atom's interval updates the counts of the groundings that watch that atom, and groundings whose count
reaches zero sit in their world's active list (one list per kind of rule: immediate, delayed, ordinary).
A timestep then costs work proportional to the changes and the active groundings, not to the size of
the program.

Why the code looks the way it does:
- Every function is compiled without numba's reference counting (`_nrt=False`): with it, each call that
  passes arrays paid two atomic operations per array, a quarter of the step time. So nothing here
  allocates; the engine (core.py) owns every buffer. When the trace or the schedule of a world needs
  more room, the kernel stops, says so in its status, and core.py grows the buffer and calls again from
  that world (`w_first`). The trace is checked before each unit of work whose rows are bounded: the
  reset (one row per atom), the application of a pass's groups (one per touched atom) and each
  immediate application (one); a world stopped inside its step resumes where it stopped (CFG_RESUME_*),
  so a step of any size fits.
- The step state is one record (StepState, below), built by backend_counting.CountingState.step_state and
  passed as one argument to step_worlds and _step_world (which read its fields into locals by name: the
  compiled backend's generator folds cfg[...], rule_i[...], rule_f[...]); the declared worlds' fused steps
  (tracelab/envs/declared/fused.py, vector_fused.py) set cfg[CFG_T] and call step_worlds with it. A new
  field is added to StepState and to step_state().
- Calls from one kernel function to another pass np.int64 values, never a bare constant or an int32
  table entry: numba compiles a callee once per distinct argument types, and each constant is a type of
  its own (Literal[int](2)), so _set_atom was compiled seven times (5 s of a first run's compile).
  tests/test_first_run.py checks that each function has one signature.
- Watches are grouped in classes: the groundings that read atom a with the same bound and sign share
  one truth test, and the groundings of a class are listed together (contiguous counts in memory).
- An immediate application has one source, so it is applied directly; only pass 0 and ordinary passes,
  where several sources may meet on one atom, go through the grouping scratch.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

EPS = 1e-9

# cause kinds of trace rows (docs/language.md, "Trace")
CAUSE_FACT, CAUSE_EXTERNAL, CAUSE_RULE, CAUSE_POLICY, CAUSE_RESET = 0, 1, 2, 3, 4
# update modes, timestep modes, inconsistency policies (indices into the tuples of program.py)
MODE_INTERSECTION, MODE_OVERRIDE = 0, 1
POLICY_RESET_FREEZE, POLICY_KEEP_OLD, POLICY_TAKE_NEW, POLICY_HULL, POLICY_ABORT = 0, 1, 2, 3, 4
# kernel status codes
STATUS_OK, STATUS_INCONSISTENT, STATUS_NO_FIXPOINT, STATUS_IMMEDIATE_LIMIT = 0, 1, 2, 3
STATUS_NOT_SETTABLE = 4  # an external fact names an atom no fact or rule can set (nothing was stepped)
STATUS_TRACE_ROOM = 5  # stopped in world err[0]: the trace buffer needs cfg[CFG_TRACE_NEED] free rows
STATUS_PEND_ROOM = 6  # stopped in world err[0] before scheduling its delayed firings: the schedule is full
STATUS_TRACE_LIMIT = 7  # a row found no room although its unit of work checked for it (a bug)
STATUS_USER_FN = 8  # stopped in world err[0]: Python computes the user annotation functions of req_i, then resumes

# column layout of the packed arrays
RULE_MODE, RULE_DELAY, RULE_IMMEDIATE, RULE_SET_STATIC = 0, 1, 2, 3  # RULE_SET_STATIC: `{set_static}` (1)
N_RULE_COLUMNS = 4
# a watched clause's flags (wc_flags, b_flags): the complement `~`, a closed predicate (`%closed`)
CLAUSE_NEGATED, CLAUSE_CLOSED = 1, 2
# per grounding (inst, int32[G, 4]): rule, head atom, rank (canonical order), kind index
INST_RULE, INST_HEAD, INST_RANK, INST_KIND = 0, 1, 2, 3
# kind indices: each grounding's rule is immediate, delayed (Δt > 0) or ordinary (Δt = 0); one active list each
KIND_IMMEDIATE, KIND_DELAYED, KIND_ORDINARY = 0, 1, 2
# groundings (joins) of rules evaluated per head grounding: listed, but fired through their head groups
KIND_AGGREGATE = 3
N_KINDS = 4
CFG_MODE, CFG_RESET, CFG_POLICY, CFG_MAX_PASSES, CFG_MAX_IMMEDIATE, CFG_T = 0, 1, 2, 3, 4, 5
CFG_TRACE_ROOM = 6  # free trace rows wanted before a traced world steps
CFG_RESUME_SCHEDULE = 7  # 1: world w_first has stepped already and only schedules its delayed firings
# a world stopped inside its step for trace room: where it resumes (phase), its pass, immediate count, heap
CFG_RESUME_PHASE, CFG_RESUME_PASS, CFG_RESUME_NIMM, CFG_RESUME_HN = 8, 9, 10, 11
CFG_TRACE_NEED = 12  # free trace rows the stopped unit of work needs
N_CFG = 13
PHASE_FRESH, PHASE_APPLY, PHASE_IMMEDIATE = 0, 1, 2  # resume: from the start, at a pass's groups, in the immediate phase
PHASE_USER = 3  # resume an ordinary pass with the user annotation functions' results (req_f)
# CFG_RESUME_SCHEDULE values: 1 the schedule had no room, 2 the delayed firings await req_f
RESUME_PEND_ROOM, RESUME_USER = 1, 2
# trace rows: int32[cap, 8] (world, t, pass_no, atom, cause_kind, cause_id, grounding, n_sources)
# and float64[cap, 4] (old_lower, old_upper, new_lower, new_upper)
TRACE_INT_COLUMNS = 8
TRACE_FLOAT_COLUMNS = 4
# stats columns
STAT_FIRINGS, STAT_REDERIVATIONS, STAT_STATIC_IGNORED, STAT_CHANGES, STAT_PASSES = 0, 1, 2, 3, 4
STAT_WATCH_VISITS, STAT_CANDIDATES = 5, 6  # work counters: count updates after changes, heap pops
N_STATS = 7

# grouping scratch (one row per touched atom, by slot): flags in S_FLAGS
F_OVERRIDE, F_INTERSECT, F_EMPTY_O, F_EMPTY_I, F_STATIC = 1, 2, 4, 8, 16
S_FLAGS, S_N, S_PRIM_KEY, S_PRIM_KIND, S_PRIM_ID, S_PRIM_INST, S_LAST_KEY = 0, 1, 2, 3, 4, 5, 6
S_LAST_KIND, S_LAST_ID, S_LAST_INST = 7, 8, 9
S_RULE_KEY, S_RULE_INST = 10, 11  # the first rule source (named by policy rows)
N_SCRATCH_INT = 12
SF_OL, SF_OU, SF_IL, SF_IU, SF_LAST_L, SF_LAST_U, SF_HULL_L, SF_HULL_U = 0, 1, 2, 3, 4, 5, 6, 7
N_SCRATCH_FLOAT = 8
# error record (err, int64[N_ERR])
E_WORLD, E_T, E_ATOM, E_OLD_KIND, E_OLD_ID, E_KIND, E_ID, E_INST, E_LAST_KIND, E_LAST_ID = range(10)
E_LAST_INST, E_DISAGREE = 10, 11
N_ERR = 12

# source keys order sources: facts, then external facts, then rule groundings by rank
KEY_STRIDE = np.int64(1) << np.int64(40)
# heap entries: rank * HEAP_SHIFT + grounding (both < 2^31)
HEAP_SHIFT = np.int64(1) << np.int64(31)
HEAP_MASK = HEAP_SHIFT - np.int64(1)

# aggregated rules (engine/aggregate_tables.py): ag_rule columns, annotation function codes, comparisons
AR_RULE, AR_KIND, AR_FN, AR_USER, AR_Q0, AR_Q1, AR_NBODY, AR_HNEG = range(8)
N_AR = 8
FN_FIXED, FN_AVERAGE, FN_WEIGHTED_AVERAGE, FN_MIN, FN_MAX, FN_AVERAGE_LOWER, FN_USER = range(7)
CMP_GE, CMP_GT, CMP_LE, CMP_LT, CMP_EQ = range(5)  # the order of program.COMPARISONS

class StepState(NamedTuple):
    """The step state: every array step_worlds reads or writes besides the step's external rows, built in
    one place (backend_counting.CountingState.step_state) and passed as one argument. Shapes: W worlds,
    A atoms, G groundings, R rules; the columns are the constants above.

    Why a NamedTuple (docs/benchmarks/history.md, "One step-state record"): numba types it by its fields'
    array types, so one compiled signature serves every program and its disk cache is hit across
    processes, and its fields are read without reference counting (a structref's need it). It is defined
    here, not in a module of its own, because numba reads its fields by position: a change of the fields
    must change this file, which stamps the kernels' disk cache and keys the compiled backend's. It holds
    the arrays, never copies them: valid until Engine.layout_version changes (a buffer replaced)."""
    cfg: np.ndarray         # int64 [N_CFG]: the step's settings and resume point (kernel.CFG_*)
    # the program (Engine)
    rule_i: np.ndarray      # int64 [R, N_RULE_COLUMNS]
    rule_f: np.ndarray      # float64 [R, 2]: the head's bound
    # the groundings (kernel_tables.KernelTables) and the active lists' layout
    inst: np.ndarray
    kind_base: np.ndarray   # int64 [N_KINDS]: where each kind's active list starts
    wc_ptr: np.ndarray
    wc_bnd: np.ndarray
    wc_flags: np.ndarray
    wc_gptr: np.ndarray
    wg: np.ndarray
    ih_ptr: np.ndarray
    ih_inst: np.ndarray
    # the program's facts and the atoms a fact can set (Engine)
    fact_i: np.ndarray
    fact_f: np.ndarray
    fact_order: np.ndarray
    settable: np.ndarray    # bool [A]
    # per world: intervals, counts, active lists, schedule (CountingState)
    lo: np.ndarray          # float64 [W, A]
    up: np.ndarray          # float64 [W, A]
    static: np.ndarray      # bool [W, A]
    last_cause: np.ndarray  # int32 [W, A, 2]
    unsat: np.ndarray       # int8 [W, G]
    act: np.ndarray         # int32 [W, G]
    act_n: np.ndarray       # int64 [W, N_KINDS]
    act_pos: np.ndarray     # int32 [W, G]
    pend: np.ndarray        # int32 [W, cap, 2]: (due, grounding)
    pend_n: np.ndarray      # int64 [W]
    # the trace, statistics and error record (Engine)
    trace_on: np.ndarray    # bool [W]
    tri: np.ndarray         # int32 [cap, TRACE_INT_COLUMNS]
    trf: np.ndarray         # float64 [cap, TRACE_FLOAT_COLUMNS]
    tr_n: np.ndarray        # int64 [1]
    stats: np.ndarray       # int64 [W, N_STATS]
    err: np.ndarray         # int64 [N_ERR]
    # scratch of a pass (CountingState)
    slot_of: np.ndarray
    touched: np.ndarray
    n_touched: np.ndarray
    si: np.ndarray
    sf: np.ndarray
    out: np.ndarray
    heap: np.ndarray
    in_heap: np.ndarray
    changed: np.ndarray
    # aggregated rules (kernel_tables.AggregateTables) and their scratch
    hg_i: np.ndarray
    hg_ptr: np.ndarray
    je_g: np.ndarray
    je_body: np.ndarray
    ag_rule: np.ndarray
    ag_cf: np.ndarray
    ag_cn: np.ndarray
    ag_q: np.ndarray
    ag_qv: np.ndarray
    mark: np.ndarray
    stamp: np.ndarray
    g_l: np.ndarray
    g_u: np.ndarray
    g_w: np.ndarray
    # user annotation functions' requests (computed by Python between kernel calls)
    req_i: np.ndarray
    req_f: np.ndarray
    req_n: np.ndarray
    pend_f: np.ndarray      # float64 [W, cap, 2]: the bound each scheduled firing sets
    # per world: its last step ended at its fixpoint and nothing but the kernel changed it since (CountingState
    # clears it on a restore, set_bounds or new groundings): no active immediate grounding would change its head
    fixed: np.ndarray       # bool [W]


kernel_jit = njit(cache=True, _nrt=False)


@kernel_jit
def _holds(lo, up, cl, cu, flags):
    """Whether an atom [lo,up] satisfies a clause [cl,cu] with `flags` (CLAUSE_NEGATED, CLAUSE_CLOSED:
    then [0,1] reads as [0,0])."""
    if flags & CLAUSE_CLOSED and lo == 0.0 and up == 1.0:
        up = 0.0
    if flags & CLAUSE_NEGATED:
        a = 1.0 - up
        b = 1.0 - lo
    else:
        a = lo
        b = up
    return a >= cl - EPS and b <= cu + EPS


@kernel_jit
def _heap_push(heap, n, key):
    i = n
    while i > 0:
        parent = (i - 1) >> 1
        pk = heap[parent]
        if pk <= key:
            break
        heap[i] = pk
        i = parent
    heap[i] = key
    return n + 1


@kernel_jit
def _heap_pop(heap, n):
    """Remove the smallest key; returns it (the caller shrinks n by one)."""
    top = heap[0]
    n -= 1
    key = heap[n]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= n:
            break
        if c + 1 < n and heap[c + 1] < heap[c]:
            c += 1
        if key <= heap[c]:
            break
        heap[i] = heap[c]
        i = c
    heap[i] = key
    return top


@kernel_jit
def _push(g, inst, heap, hn, in_heap):
    """Make immediate grounding g a candidate of the running immediate phase (once)."""
    if in_heap[g]:
        return hn
    in_heap[g] = True
    return _heap_push(heap, hn, np.int64(inst[g, INST_RANK]) * HEAP_SHIFT + g)


@kernel_jit
def _applies(w, g, lo, up, static, rule_i, rule_f, policy, inst):
    """Would active grounding g, applied now in world w, change its head (or meet an inconsistency
    under abort)? Only such groundings become candidates: one that would not can only become one when
    its head changes or it becomes active again, and both push it then."""
    a = inst[g, INST_HEAD]
    if static[w, a]:
        return False
    r = inst[g, INST_RULE]
    if rule_i[r, RULE_SET_STATIC] == 1:
        return True  # applying it freezes the head, a change of its own
    l = rule_f[r, 0]
    u = rule_f[r, 1]
    cl = lo[w, a]
    cu = up[w, a]
    if rule_i[r, RULE_MODE] == MODE_OVERRIDE:
        rl, ru = l, u
    else:
        rl, ru = max(cl, l), min(cu, u)
    if rl > ru + EPS:
        if policy == POLICY_KEEP_OLD:
            return False
        if policy == POLICY_ABORT:
            return True
        if policy == POLICY_RESET_FREEZE:
            rl, ru = 0.0, 1.0
        elif policy == POLICY_TAKE_NEW:
            rl, ru = l, u
        else:
            rl, ru = min(cl, l), max(cu, u)
    return rl != cl or ru != cu


@kernel_jit
def _set_atom(w, t, pass_no, a, cl, cu, nl, nu, kind, cid, g_src, nsrc, skip, lo, up, last_cause,
              static, rule_i, rule_f, policy, trace_on, tri, trf, tr_n, stats, wc_ptr, wc_bnd, wc_flags, wc_gptr, wg, unsat, inst,
              act, act_n, act_pos, kind_base, ih_ptr, ih_inst, heap, hn, in_heap):
    """Change atom a of world w from [cl,cu] to [nl,nu]: log the row, update the counts of the
    groundings that read a (activating and deactivating them), and make the immediate groundings
    that became active, or that set a, candidates; except `skip`, an immediate grounding that just
    set a consistently (applying it again would change nothing).
    Returns the new heap size, or -1 when the trace buffer is full."""
    if trace_on[w]:
        n = tr_n[0]
        if n >= tri.shape[0]:
            return -1
        tri[n, 0] = w
        tri[n, 1] = t
        tri[n, 2] = pass_no
        tri[n, 3] = a
        tri[n, 4] = kind
        tri[n, 5] = cid
        tri[n, 6] = g_src
        tri[n, 7] = nsrc
        trf[n, 0] = cl
        trf[n, 1] = cu
        trf[n, 2] = nl
        trf[n, 3] = nu
        tr_n[0] = n + 1
    lo[w, a] = nl
    up[w, a] = nu
    last_cause[w, a, 0] = kind
    last_cause[w, a, 1] = cid
    stats[w, STAT_CHANGES] += 1
    visits = 0
    for c in range(wc_ptr[a], wc_ptr[a + 1]):
        bl = wc_bnd[c, 0]
        bu = wc_bnd[c, 1]
        flags = wc_flags[c]
        was = _holds(cl, cu, bl, bu, flags)
        now = _holds(nl, nu, bl, bu, flags)
        if was == now:
            continue
        e0 = wc_gptr[c]
        e1 = wc_gptr[c + 1]
        visits += e1 - e0
        if was:  # the clause stopped holding: one more unsatisfied clause
            for e in range(e0, e1):
                g = wg[e]
                u = unsat[w, g] + 1
                unsat[w, g] = u
                if u == 1:  # was active: leave its kind's list (swap with the last)
                    k = inst[g, INST_KIND]
                    base = kind_base[k]
                    p = act_pos[w, g]
                    last_i = act_n[w, k] - 1
                    last = act[w, base + last_i]
                    act[w, base + p] = last
                    act_pos[w, last] = p
                    act_pos[w, g] = -1
                    act_n[w, k] = last_i
        else:
            for e in range(e0, e1):
                g = wg[e]
                u = unsat[w, g] - 1
                unsat[w, g] = u
                if u == 0:  # became active: join its kind's list
                    k = inst[g, INST_KIND]
                    p = act_n[w, k]
                    act[w, kind_base[k] + p] = g
                    act_pos[w, g] = p
                    act_n[w, k] = p + 1
                    if k == KIND_IMMEDIATE and _applies(w, g, lo, up, static, rule_i, rule_f, policy, inst):
                        hn = _push(g, inst, heap, hn, in_heap)
    stats[w, STAT_WATCH_VISITS] += visits
    # the immediate groundings that set a may now change it (back)
    for k in range(ih_ptr[a], ih_ptr[a + 1]):
        g = ih_inst[k]
        if g != skip and unsat[w, g] == 0 and _applies(w, g, lo, up, static, rule_i, rule_f, policy, inst):
            hn = _push(g, inst, heap, hn, in_heap)
    return hn


@kernel_jit
def _add_source(a, l, u, override, key, kind, cid, g_src, static_src, slot_of, touched, n_touched, si, sf):
    """Add one source's bound for atom a to the pending group of this pass (scratch row slot_of[a])."""
    s = slot_of[a]
    if s < 0:
        s = n_touched[0]
        n_touched[0] = s + 1
        slot_of[a] = s
        touched[s] = a
        flags = 0
        si[s, S_N] = 0
        si[s, S_PRIM_KEY] = key
        si[s, S_PRIM_KIND] = kind
        si[s, S_PRIM_ID] = cid
        si[s, S_PRIM_INST] = g_src
        si[s, S_LAST_KEY] = key
        si[s, S_LAST_KIND] = kind
        si[s, S_LAST_ID] = cid
        si[s, S_LAST_INST] = g_src
        si[s, S_RULE_KEY] = key if kind == CAUSE_RULE else -1
        si[s, S_RULE_INST] = g_src if kind == CAUSE_RULE else -1
        sf[s, SF_LAST_L] = l
        sf[s, SF_LAST_U] = u
        sf[s, SF_HULL_L] = l
        sf[s, SF_HULL_U] = u
    else:
        flags = si[s, S_FLAGS]
        if kind == CAUSE_RULE and (si[s, S_RULE_KEY] < 0 or key < si[s, S_RULE_KEY]):
            si[s, S_RULE_KEY] = key
            si[s, S_RULE_INST] = g_src
        if key < si[s, S_PRIM_KEY]:
            si[s, S_PRIM_KEY] = key
            si[s, S_PRIM_KIND] = kind
            si[s, S_PRIM_ID] = cid
            si[s, S_PRIM_INST] = g_src
        if key >= si[s, S_LAST_KEY]:
            si[s, S_LAST_KEY] = key
            si[s, S_LAST_KIND] = kind
            si[s, S_LAST_ID] = cid
            si[s, S_LAST_INST] = g_src
            sf[s, SF_LAST_L] = l
            sf[s, SF_LAST_U] = u
        sf[s, SF_HULL_L] = min(sf[s, SF_HULL_L], l)
        sf[s, SF_HULL_U] = max(sf[s, SF_HULL_U], u)
    si[s, S_N] += 1
    if static_src:
        flags |= F_STATIC
    if override:
        if flags & F_OVERRIDE == 0:
            flags |= F_OVERRIDE
            sf[s, SF_OL] = l
            sf[s, SF_OU] = u
        else:
            sf[s, SF_OL] = max(sf[s, SF_OL], l)
            sf[s, SF_OU] = min(sf[s, SF_OU], u)
        if sf[s, SF_OL] > sf[s, SF_OU] + EPS:
            flags |= F_EMPTY_O
    else:
        if flags & F_INTERSECT == 0:
            flags |= F_INTERSECT
            sf[s, SF_IL] = l
            sf[s, SF_IU] = u
        else:
            sf[s, SF_IL] = max(sf[s, SF_IL], l)
            sf[s, SF_IU] = min(sf[s, SF_IU], u)
        if sf[s, SF_IL] > sf[s, SF_IU] + EPS:
            flags |= F_EMPTY_I
    si[s, S_FLAGS] = flags


@kernel_jit
def _resolve(cl, cu, s, policy, si, sf, out):
    """The new interval of an atom (current [cl,cu]) after its pending group in scratch row s:
    docs/language.md, 'Updating an atom'. Writes (lower, upper, inconsistent, freeze, incoming
    sources disagree) into out."""
    flags = si[s, S_FLAGS]
    inconsistent = (flags & (F_EMPTY_O | F_EMPTY_I)) != 0
    if flags & F_OVERRIDE:
        bl = sf[s, SF_OL]
        bu = sf[s, SF_OU]
    else:
        bl = cl
        bu = cu
    if flags & F_INTERSECT:
        rl = max(bl, sf[s, SF_IL])
        ru = min(bu, sf[s, SF_IU])
    else:
        rl = bl
        ru = bu
    if rl > ru + EPS:
        inconsistent = True
    freeze = False
    if inconsistent:
        if policy == POLICY_RESET_FREEZE:
            rl, ru, freeze = 0.0, 1.0, True
        elif policy == POLICY_KEEP_OLD:
            rl, ru = cl, cu
        elif policy == POLICY_TAKE_NEW:
            # the incoming sources alone (Mo ∩ Mi), if they agree; else the last source's bound
            nl, nu = 0.0, 1.0
            ok = (flags & (F_EMPTY_O | F_EMPTY_I)) == 0
            if flags & F_OVERRIDE:
                nl, nu = sf[s, SF_OL], sf[s, SF_OU]
            if flags & F_INTERSECT:
                nl, nu = max(nl, sf[s, SF_IL]), min(nu, sf[s, SF_IU])
            if ok and nl <= nu + EPS:
                rl, ru = nl, nu
            else:
                rl, ru = sf[s, SF_LAST_L], sf[s, SF_LAST_U]
        elif policy == POLICY_HULL:
            rl = min(cl, sf[s, SF_HULL_L])
            ru = max(cu, sf[s, SF_HULL_U])
    incoming_disagree = (flags & (F_EMPTY_O | F_EMPTY_I)) != 0
    if (flags & F_OVERRIDE) and (flags & F_INTERSECT):
        if max(sf[s, SF_OL], sf[s, SF_IL]) > min(sf[s, SF_OU], sf[s, SF_IU]) + EPS:
            incoming_disagree = True
    out[0] = rl
    out[1] = ru
    out[2] = 1.0 if inconsistent else 0.0
    out[3] = 1.0 if freeze else 0.0
    out[4] = 1.0 if incoming_disagree else 0.0


@kernel_jit
def _sort_small(a, n):
    """Sort a[:n] in place (insertion sort: a pass usually touches few atoms; shell gaps beyond)."""
    gap = 1
    while gap < n // 3:
        gap = 3 * gap + 1
    while gap >= 1:
        for i in range(gap, n):
            x = a[i]
            j = i - gap
            while j >= 0 and a[j] > x:
                a[j + gap] = a[j]
                j -= gap
            a[j + gap] = x
        gap //= 3


@kernel_jit
def _apply_groups(w, t, pass_no, policy, rule_i, rule_f, slot_of, touched, n_touched, si, sf, out, lo, up,
                  static, last_cause, trace_on, tri, trf, tr_n, stats, err, wc_ptr, wc_bnd, wc_flags, wc_gptr, wg,
                  unsat, inst, act, act_n, act_pos, kind_base, ih_ptr, ih_inst, heap, hn, in_heap,
                  changed):
    """Apply every pending group of this pass (one per touched atom), in atom order.
    changed[0] counts the atoms that changed. Returns (status, heap size)."""
    n = n_touched[0]
    _sort_small(touched, n)
    status = STATUS_OK
    for k in range(n):
        a = touched[k]
        s = slot_of[a]
        slot_of[a] = -1
        if status != STATUS_OK:
            continue  # keep clearing the slots
        nsrc = si[s, S_N]
        kind = si[s, S_PRIM_KIND]
        if kind == CAUSE_RULE:
            stats[w, STAT_FIRINGS] += nsrc
        if static[w, a]:
            stats[w, STAT_STATIC_IGNORED] += nsrc
            continue
        cl = lo[w, a]
        cu = up[w, a]
        _resolve(cl, cu, s, policy, si, sf, out)
        nl = out[0]
        nu = out[1]
        inconsistent = out[2] > 0.5
        if inconsistent and policy == POLICY_ABORT:
            err[E_WORLD] = w
            err[E_T] = t
            err[E_ATOM] = a
            err[E_OLD_KIND] = last_cause[w, a, 0]
            err[E_OLD_ID] = last_cause[w, a, 1]
            err[E_KIND] = kind
            err[E_ID] = si[s, S_PRIM_ID]
            err[E_INST] = si[s, S_PRIM_INST]
            err[E_LAST_KIND] = si[s, S_LAST_KIND]
            err[E_LAST_ID] = si[s, S_LAST_ID]
            err[E_LAST_INST] = si[s, S_LAST_INST]
            err[E_DISAGREE] = 1 if out[4] > 0.5 else 0
            status = STATUS_INCONSISTENT
            continue
        if nl != cl or nu != cu:
            changed[0] += 1
            if inconsistent:
                hn = _set_atom(w, t, pass_no, np.int64(a), cl, cu, nl, nu, np.int64(CAUSE_POLICY), policy,
                               si[s, S_RULE_INST], nsrc, np.int64(-1), lo, up, last_cause, static, rule_i, rule_f, policy, trace_on, tri, trf, tr_n, stats, wc_ptr, wc_bnd, wc_flags,
                               wc_gptr, wg, unsat, inst, act, act_n, act_pos, kind_base, ih_ptr, ih_inst,
                               heap, hn, in_heap)
            else:
                hn = _set_atom(w, t, pass_no, np.int64(a), cl, cu, nl, nu, kind, si[s, S_PRIM_ID], si[s, S_PRIM_INST],
                               nsrc, np.int64(-1), lo, up, last_cause, static, rule_i, rule_f, policy, trace_on, tri, trf, tr_n, stats, wc_ptr, wc_bnd,
                               wc_flags, wc_gptr, wg, unsat, inst, act, act_n, act_pos, kind_base, ih_ptr,
                               ih_inst, heap, hn, in_heap)
            if hn < 0:
                status = STATUS_TRACE_LIMIT
                err[E_WORLD] = w
                continue
        elif kind == CAUSE_RULE:
            stats[w, STAT_REDERIVATIONS] += nsrc
        if out[3] > 0.5 or si[s, S_FLAGS] & F_STATIC:
            static[w, a] = True
    n_touched[0] = 0
    return status, hn


@kernel_jit
def _one_source(cl, cu, l, u, override, policy, out):
    """The result of one source [l,u] on an atom now [cl,cu] (an immediate application):
    writes (lower, upper, inconsistent, freeze) into out."""
    if override:
        rl, ru = l, u
    else:
        rl, ru = max(cl, l), min(cu, u)
    inconsistent = rl > ru + EPS
    freeze = False
    if inconsistent:
        if policy == POLICY_RESET_FREEZE:
            rl, ru, freeze = 0.0, 1.0, True
        elif policy == POLICY_KEEP_OLD:
            rl, ru = cl, cu
        elif policy == POLICY_TAKE_NEW:
            rl, ru = l, u
        elif policy == POLICY_HULL:
            rl, ru = min(cl, l), max(cu, u)
    out[0] = rl
    out[1] = ru
    out[2] = 1.0 if inconsistent else 0.0
    out[3] = 1.0 if freeze else 0.0


@kernel_jit
def _reset_world(w, t, policy, rule_i, rule_f, lo, up, static, last_cause, trace_on, tri, trf, tr_n, stats, wc_ptr, wc_bnd, wc_flags,
                 wc_gptr, wg, unsat, inst, act, act_n, act_pos, kind_base, ih_ptr, ih_inst, heap, hn, in_heap):
    """`%timesteps reset`: every non-static atom goes back to [0,1] at the start of a step."""
    for a in range(lo.shape[1]):
        if static[w, a]:
            continue
        cl = lo[w, a]
        cu = up[w, a]
        if cl == 0.0 and cu == 1.0:
            continue
        hn = _set_atom(w, t, np.int64(0), a, cl, cu, 0.0, 1.0, np.int64(CAUSE_RESET), np.int64(-1), np.int64(-1),
                       np.int64(0), np.int64(-1), lo, up, last_cause, static, rule_i, rule_f, policy, trace_on,
                       tri, trf, tr_n, stats, wc_ptr, wc_bnd, wc_flags, wc_gptr, wg, unsat, inst, act, act_n,
                       act_pos, kind_base, ih_ptr, ih_inst, heap, hn, in_heap)
        if hn < 0:
            return hn
    return hn


@kernel_jit
def step_worlds(s, w_first, ext_ptr, ext_i, ext_f):
    """Compute timestep cfg[CFG_T] for worlds w_first.. in order; s: the StepState,
    ext_*: the step's external rows, world w's from ext_ptr[w] to ext_ptr[w + 1]. Returns (status, world):
    STATUS_OK and the number of worlds, or a status and the world it concerns (STATUS_TRACE_ROOM /
    STATUS_PEND_ROOM: grow that buffer and call again from that world)."""
    # fields read by name (the compiled backend's generator folds cfg[...], rule_i[...] and rule_f[...])
    cfg, rule_i, rule_f, err, req_i, req_f, req_n = s.cfg, s.rule_i, s.rule_f, s.err, s.req_i, s.req_f, s.req_n
    lo, act, act_n, inst, hg_i = s.lo, s.act, s.act_n, s.inst, s.hg_i
    pend, pend_n, pend_f = s.pend, s.pend_n, s.pend_f
    ag_rule, out, trace_on, tri, tr_n, settable = s.ag_rule, s.out, s.trace_on, s.tri, s.tr_n, s.settable
    t = cfg[CFG_T]
    prog_mode = cfg[CFG_MODE]
    policy = cfg[CFG_POLICY]
    max_passes = cfg[CFG_MAX_PASSES]
    max_immediate = cfg[CFG_MAX_IMMEDIATE]
    room = cfg[CFG_TRACE_ROOM]
    n_worlds = lo.shape[0]
    fact_override = prog_mode == MODE_OVERRIDE
    if w_first == 0 and cfg[CFG_RESUME_SCHEDULE] == 0:
        for e in range(ext_ptr[n_worlds]):  # checked before any world steps: a refusal changes nothing
            if not settable[ext_i[e, 0]]:
                err[E_ATOM] = ext_i[e, 0]
                return STATUS_NOT_SETTABLE, 0
    for w in range(w_first, n_worlds):
        resume = cfg[CFG_RESUME_SCHEDULE] if w == w_first else 0
        cfg[CFG_RESUME_SCHEDULE] = 0
        if resume == RESUME_USER:  # the delayed firings of user functions, computed by Python
            n = pend_n[w]
            for i in range(req_n[0]):
                h = req_i[i, 0]
                pend[w, n, 0] = t + rule_i[ag_rule[hg_i[h, 0], AR_RULE], RULE_DELAY]
                pend[w, n, 1] = req_i[i, 1]
                pend_f[w, n, 0] = req_f[i, 0]
                pend_f[w, n, 1] = req_f[i, 1]
                n += 1
            pend_n[w] = n
            req_n[0] = 0
            continue
        if resume == 0:
            if cfg[CFG_RESUME_PHASE] == PHASE_FRESH and trace_on[w] and tri.shape[0] - tr_n[0] < room:
                err[E_WORLD] = w
                cfg[CFG_TRACE_NEED] = room
                return STATUS_TRACE_ROOM, w
            status = _step_world(s, w, t, fact_override, policy, max_passes, max_immediate,
                                 cfg[CFG_RESET] == 1, ext_ptr, ext_i, ext_f)
            if status != STATUS_OK:
                return status, w
        # delayed rules read the final interpretation of t and schedule their heads (room for every
        # active grounding and every head group)
        n_del = act_n[w, KIND_DELAYED]
        n = pend_n[w]
        if n + n_del + hg_i.shape[0] > pend.shape[1]:
            err[E_WORLD] = w
            return STATUS_PEND_ROOM, w
        base = s.kind_base[KIND_DELAYED]
        for k in range(n_del):
            g = act[w, base + k]
            r = inst[g, INST_RULE]
            pend[w, n, 0] = t + rule_i[r, RULE_DELAY]
            pend[w, n, 1] = g
            pend_f[w, n, 0] = rule_f[r, 0]
            pend_f[w, n, 1] = rule_f[r, 1]
            n += 1
        for h in range(hg_i.shape[0]):
            ai = hg_i[h, 0]
            if ag_rule[ai, AR_KIND] != KIND_DELAYED:
                continue
            g = _agg_fire(w, rule_f, hg_i, s.hg_ptr, s.je_g, s.je_body, ag_rule, s.ag_cf, s.ag_cn, s.ag_q, s.ag_qv,
                          lo, s.up, s.unsat, s.mark, s.stamp, s.g_l, s.g_u, s.g_w, req_i, req_n, out, h)
            if g >= 0:
                pend[w, n, 0] = t + rule_i[ag_rule[ai, AR_RULE], RULE_DELAY]
                pend[w, n, 1] = g
                pend_f[w, n, 0] = out[0]
                pend_f[w, n, 1] = out[1]
                n += 1
        pend_n[w] = n
        if req_n[0] > 0:  # Python computes the user functions, then this world schedules them
            cfg[CFG_RESUME_SCHEDULE] = RESUME_USER
            err[E_WORLD] = w
            return STATUS_USER_FN, w
    return STATUS_OK, n_worlds


@kernel_jit
def _step_world(s, w, t, fact_override, policy, max_passes, max_immediate, reset, ext_ptr, ext_i,
                ext_f):
    """One world's timestep t up to its fixpoint (docs/language.md, 'One timestep t'), without the
    scheduling of delayed rules. Returns a status (STATUS_TRACE_ROOM: resume by calling again, cfg says
    where)."""
    # the step state's fields by name, as the callees take them
    cfg, rule_i, rule_f, inst, kind_base = s.cfg, s.rule_i, s.rule_f, s.inst, s.kind_base
    wc_ptr, wc_bnd, wc_flags, wc_gptr, wg = s.wc_ptr, s.wc_bnd, s.wc_flags, s.wc_gptr, s.wg
    ih_ptr, ih_inst = s.ih_ptr, s.ih_inst
    fact_i, fact_f, fact_order = s.fact_i, s.fact_f, s.fact_order
    lo, up, static, last_cause, unsat = s.lo, s.up, s.static, s.last_cause, s.unsat
    act, act_n, act_pos, pend, pend_n, pend_f = s.act, s.act_n, s.act_pos, s.pend, s.pend_n, s.pend_f
    trace_on, tri, trf, tr_n, stats, err = s.trace_on, s.tri, s.trf, s.tr_n, s.stats, s.err
    slot_of, touched, n_touched, si, sf, out = s.slot_of, s.touched, s.n_touched, s.si, s.sf, s.out
    heap, in_heap, changed = s.heap, s.in_heap, s.changed
    hg_i, hg_ptr, je_g, je_body = s.hg_i, s.hg_ptr, s.je_g, s.je_body
    ag_rule, ag_cf, ag_cn = s.ag_rule, s.ag_cf, s.ag_cn
    ag_q, ag_qv, mark, stamp, g_l, g_u, g_w = s.ag_q, s.ag_qv, s.mark, s.stamp, s.g_l, s.g_u, s.g_w
    req_i, req_f, req_n = s.req_i, s.req_f, s.req_n
    phase = cfg[CFG_RESUME_PHASE]
    cfg[CFG_RESUME_PHASE] = PHASE_FRESH
    pass_no = cfg[CFG_RESUME_PASS] if phase != PHASE_FRESH else 0
    n_immediate = cfg[CFG_RESUME_NIMM] if phase != PHASE_FRESH else 0
    hn = cfg[CFG_RESUME_HN] if phase != PHASE_FRESH else 0
    look = True  # pass 0 looks at every active immediate grounding (not needed after a fixpoint: `fixed`)
    if phase == PHASE_FRESH:
        # 1. start of the step
        look = not s.fixed[w] or (reset and t > 0)
        s.fixed[w] = False
        if reset and t > 0:
            if trace_on[w] and tri.shape[0] - tr_n[0] < lo.shape[1]:
                return _pause(cfg, err, w, np.int64(PHASE_FRESH), np.int64(0), np.int64(0), np.int64(0),
                              np.int64(lo.shape[1]))
            hn = _reset_world(w, t, policy, rule_i, rule_f, lo, up, static, last_cause, trace_on, tri, trf, tr_n, stats,
                              wc_ptr, wc_bnd, wc_flags, wc_gptr, wg, unsat, inst, act, act_n, act_pos, kind_base, ih_ptr,
                              ih_inst, heap, hn, in_heap)
            if hn < 0:
                err[E_WORLD] = w
                return STATUS_TRACE_LIMIT
        _collect_pass0(w, t, fact_override, rule_i, inst, fact_i, fact_f, fact_order, ext_ptr, ext_i,
                       ext_f, pend, pend_f, pend_n, slot_of, touched, n_touched, si, sf)
        phase = PHASE_APPLY
    if phase == PHASE_APPLY and pass_no == 0:
        if trace_on[w] and tri.shape[0] - tr_n[0] < n_touched[0]:
            return _pause(cfg, err, w, np.int64(PHASE_APPLY), np.int64(0), np.int64(0), hn, n_touched[0])
        changed[0] = 0
        status, hn = _apply_groups(w, t, np.int64(0), policy, rule_i, rule_f, slot_of, touched, n_touched, si, sf, out,
                                   lo, up, static, last_cause, trace_on, tri, trf, tr_n, stats, err, wc_ptr, wc_bnd,
                                   wc_flags, wc_gptr, wg, unsat, inst, act, act_n, act_pos, kind_base, ih_ptr, ih_inst,
                                   heap, hn, in_heap, changed)
        if status != STATUS_OK:
            return status
        # every active immediate grounding is a candidate of the first immediate phase; after that, a
        # grounding becomes a candidate when it becomes active or an atom it sets changes (_set_atom). After a
        # fixpoint none applies but those pass 0's changes pushed (~1,000 looks a step at 20 agents a team)
        if look:
            base = kind_base[KIND_IMMEDIATE]
            for k in range(act_n[w, KIND_IMMEDIATE]):
                g = act[w, base + k]
                if _applies(w, g, lo, up, static, rule_i, rule_f, policy, inst):
                    hn = _push(g, inst, heap, hn, in_heap)
        pass_no = 1
        phase = PHASE_FRESH
    # 3. fixpoint: immediate phase, then one simultaneous ordinary pass, until nothing changes
    while True:
        if phase == PHASE_USER:  # an ordinary pass resumed with its user functions' bounds
            _agg_user_sources(rule_i, inst, hg_i, ag_rule, req_i, req_f, req_n, slot_of, touched, n_touched, si, sf)
            phase = PHASE_FRESH
            if trace_on[w] and tri.shape[0] - tr_n[0] < n_touched[0]:
                return _pause(cfg, err, w, np.int64(PHASE_APPLY), pass_no, n_immediate, hn, n_touched[0])
        elif phase != PHASE_APPLY:
            # immediate phase: apply the first (lowest rank) active immediate grounding that would change
            # its head, one at a time
            while hn > 0:
                if trace_on[w] and tr_n[0] >= tri.shape[0]:
                    return _pause(cfg, err, w, np.int64(PHASE_IMMEDIATE), pass_no, n_immediate, hn, np.int64(1))
                key = _heap_pop(heap, hn)
                hn -= 1
                g = key & HEAP_MASK
                in_heap[g] = False
                stats[w, STAT_CANDIDATES] += 1
                if unsat[w, g] != 0:
                    continue
                a = inst[g, INST_HEAD]
                if static[w, a]:
                    continue
                r = inst[g, INST_RULE]
                cl = lo[w, a]
                cu = up[w, a]
                _one_source(cl, cu, rule_f[r, 0], rule_f[r, 1], rule_i[r, RULE_MODE] == MODE_OVERRIDE, policy, out)
                inconsistent = out[2] > 0.5
                abort = inconsistent and policy == POLICY_ABORT
                set_static = rule_i[r, RULE_SET_STATIC] == 1
                if not abort and out[0] == cl and out[1] == cu and not set_static:
                    continue  # would not change its head
                n_immediate += 1
                if n_immediate > max_immediate:
                    err[E_WORLD] = w
                    err[E_T] = t
                    err[E_ATOM] = a
                    return STATUS_IMMEDIATE_LIMIT
                stats[w, STAT_FIRINGS] += 1
                if abort:
                    err[E_WORLD] = w
                    err[E_T] = t
                    err[E_ATOM] = a
                    err[E_OLD_KIND] = last_cause[w, a, 0]
                    err[E_OLD_ID] = last_cause[w, a, 1]
                    err[E_KIND] = CAUSE_RULE
                    err[E_ID] = r
                    err[E_INST] = g
                    err[E_LAST_KIND] = CAUSE_RULE
                    err[E_LAST_ID] = r
                    err[E_LAST_INST] = g
                    err[E_DISAGREE] = 0
                    return STATUS_INCONSISTENT
                freeze = out[3] > 0.5 or set_static
                if out[0] == cl and out[1] == cu:  # a {set_static} firing that only freezes the head
                    stats[w, STAT_REDERIVATIONS] += 1
                elif inconsistent:
                    hn = _set_atom(w, t, pass_no, np.int64(a), cl, cu, out[0], out[1], np.int64(CAUSE_POLICY), policy,
                                   g, np.int64(1), np.int64(-1), lo, up,
                                   last_cause, static, rule_i, rule_f, policy, trace_on, tri, trf, tr_n, stats, wc_ptr,
                                   wc_bnd, wc_flags, wc_gptr, wg, unsat, inst, act, act_n, act_pos, kind_base, ih_ptr,
                                   ih_inst, heap, hn, in_heap)
                else:
                    hn = _set_atom(w, t, pass_no, np.int64(a), cl, cu, out[0], out[1], np.int64(CAUSE_RULE),
                                   np.int64(r), g, np.int64(1), g, lo, up, last_cause,
                                   static, rule_i, rule_f, policy, trace_on, tri, trf, tr_n, stats, wc_ptr, wc_bnd,
                                   wc_flags, wc_gptr, wg, unsat, inst, act, act_n, act_pos, kind_base, ih_ptr, ih_inst,
                                   heap, hn, in_heap)
                if hn < 0:
                    err[E_WORLD] = w
                    return STATUS_TRACE_LIMIT
                if freeze:
                    static[w, a] = True
            # ordinary pass: every active Δt = 0 grounding fires; heads applied together per atom
            base = kind_base[KIND_ORDINARY]
            for k in range(act_n[w, KIND_ORDINARY]):
                g = act[w, base + k]
                r = inst[g, INST_RULE]
                _add_source(np.int64(inst[g, INST_HEAD]), rule_f[r, 0], rule_f[r, 1],
                            rule_i[r, RULE_MODE] == MODE_OVERRIDE, 2 * KEY_STRIDE + inst[g, INST_RANK],
                            np.int64(CAUSE_RULE), np.int64(r), np.int64(g), rule_i[r, RULE_SET_STATIC] == 1,
                            slot_of, touched, n_touched, si, sf)
            if hg_i.shape[0] > 0:
                _agg_pass(w, rule_i, rule_f, inst, hg_i, hg_ptr, je_g, je_body, ag_rule, ag_cf, ag_cn, ag_q, ag_qv, lo,
                          up, unsat, mark, stamp, g_l, g_u, g_w, req_i, req_n, out, slot_of, touched, n_touched, si, sf)
                if req_n[0] > 0:  # Python computes the user annotation functions, then the pass goes on
                    _pause(cfg, err, w, np.int64(PHASE_USER), pass_no, n_immediate, hn, np.int64(0))
                    return STATUS_USER_FN
            if trace_on[w] and tri.shape[0] - tr_n[0] < n_touched[0]:
                return _pause(cfg, err, w, np.int64(PHASE_APPLY), pass_no, n_immediate, hn, n_touched[0])
        phase = PHASE_FRESH
        changed[0] = 0
        status, hn = _apply_groups(w, t, pass_no, policy, rule_i, rule_f, slot_of, touched, n_touched, si, sf, out, lo, up,
                                   static, last_cause, trace_on, tri, trf, tr_n, stats, err, wc_ptr, wc_bnd,
                                   wc_flags, wc_gptr, wg, unsat, inst, act, act_n, act_pos, kind_base, ih_ptr,
                                   ih_inst, heap, hn, in_heap, changed)
        if status != STATUS_OK:
            return status
        stats[w, STAT_PASSES] += 1
        if changed[0] == 0:
            break
        pass_no += 1
        if pass_no > max_passes:
            err[E_WORLD] = w
            err[E_T] = t
            err[E_ATOM] = -1
            return STATUS_NO_FIXPOINT
    s.fixed[w] = True
    return STATUS_OK


@kernel_jit
def _pause(cfg, err, w, phase, pass_no, n_immediate, hn, need):
    """Stop world w's step for trace room: remember where it resumes and how many rows it needs."""
    cfg[CFG_RESUME_PHASE] = phase
    cfg[CFG_RESUME_PASS] = pass_no
    cfg[CFG_RESUME_NIMM] = n_immediate
    cfg[CFG_RESUME_HN] = hn
    cfg[CFG_TRACE_NEED] = need
    err[E_WORLD] = w
    return STATUS_TRACE_ROOM


@kernel_jit
def _collect_pass0(w, t, fact_override, rule_i, inst, fact_i, fact_f, fact_order, ext_ptr, ext_i, ext_f,
                   pend, pend_f, pend_n, slot_of, touched, n_touched, si, sf):
    """The sources of pass 0 into the grouping scratch: program facts in their window, external facts,
    firings scheduled for t (taken off the schedule)."""
    for k in range(fact_order.shape[0]):
        f = fact_order[k]
        if fact_i[f, 2] < t:
            break
        if fact_i[f, 1] <= t:
            _add_source(np.int64(fact_i[f, 0]), fact_f[f, 0], fact_f[f, 1], fact_override, np.int64(f),
                        np.int64(CAUSE_FACT), np.int64(f), np.int64(-1),
                        fact_i[f, 3] == 1, slot_of, touched, n_touched, si, sf)
    for e in range(ext_ptr[w], ext_ptr[w + 1]):
        _add_source(ext_i[e, 0], ext_f[e, 0], ext_f[e, 1], fact_override, KEY_STRIDE + ext_i[e, 2],
                    np.int64(CAUSE_EXTERNAL), ext_i[e, 2], np.int64(-1), ext_i[e, 1] == 1,
                    slot_of, touched, n_touched, si, sf)
    kept = 0
    for p in range(pend_n[w]):
        g = pend[w, p, 1]
        if pend[w, p, 0] == t:
            r = inst[g, INST_RULE]
            _add_source(np.int64(inst[g, INST_HEAD]), pend_f[w, p, 0], pend_f[w, p, 1],
                        rule_i[r, RULE_MODE] == MODE_OVERRIDE, 2 * KEY_STRIDE + inst[g, INST_RANK],
                        np.int64(CAUSE_RULE), np.int64(r), np.int64(g), rule_i[r, RULE_SET_STATIC] == 1,
                        slot_of, touched, n_touched, si, sf)
        else:
            pend[w, kept, 0] = pend[w, p, 0]
            pend[w, kept, 1] = g
            pend_f[w, kept, 0] = pend_f[w, p, 0]
            pend_f[w, kept, 1] = pend_f[w, p, 1]
            kept += 1
    pend_n[w] = kept


# ------------------------------------------------------------------ rules evaluated per head grounding

@kernel_jit
def _compare(op, n, d, percent, value):
    """A quantifier's test: n of d candidates against a count, or n/d against a percentage (no
    candidates: a percentage fails)."""
    if percent:
        if d == 0:
            return False
        lhs = n * 100.0
        rhs = value * d
    else:
        lhs = float(n)
        rhs = value
    if op == CMP_GE:
        return lhs >= rhs
    if op == CMP_GT:
        return lhs > rhs
    if op == CMP_LE:
        return lhs <= rhs
    if op == CMP_LT:
        return lhs < rhs
    return lhs == rhs


@kernel_jit
def _candidates(w, ci, e0, e1, unsat, je_g, je_body, mark, stamp):
    """The distinct atoms of clause ci over the active joins e0..e1 of a head group, in join order, into
    mark[1] (mark[0] holds stamps by atom); returns how many."""
    stamp[0] += 1
    st = stamp[0]
    n = 0
    for e in range(e0, e1):
        if unsat[w, je_g[e]] != 0:
            continue
        a = je_body[e, ci]
        if mark[0, a] == st:
            continue
        mark[0, a] = st
        mark[1, n] = a
        n += 1
    return n


@kernel_jit
def _agg_eval(w, h, lo, up, unsat, hg_i, hg_ptr, je_g, je_body, ag_rule, ag_cf, ag_cn, ag_q, ag_qv, mark,
              stamp, g_l, g_u, g_w):
    """Head group h in world w (docs/language.md, "Quantifiers"): returns (grounding, k) with the firing's
    grounding (the first active join whose quantified atoms hold, else the first active join) or -1 when
    the group does not fire, and the k atoms that feed
    its annotation function in g_l, g_u, g_w (each clause's distinct atoms that hold, clause by clause,
    joins in rank order)."""
    e0 = hg_ptr[h]
    e1 = hg_ptr[h + 1]
    rep = -1
    for e in range(e0, e1):
        if unsat[w, je_g[e]] == 0:
            rep = je_g[e]
            break
    if rep < 0:
        return -1, 0
    ai = hg_i[h, 0]
    for qi in range(ag_rule[ai, AR_Q0], ag_rule[ai, AR_Q1]):
        ci = ag_q[qi, 0]
        available_only = ag_q[qi, 3] == 1
        d = 0
        n = 0
        for i in range(_candidates(w, ci, e0, e1, unsat, je_g, je_body, mark, stamp)):
            a = mark[1, i]
            if available_only and lo[w, a] == 0.0 and up[w, a] == 1.0:
                continue  # never set (or back at [0,1]): not available
            d += 1
            if _holds(lo[w, a], up[w, a], ag_cf[ai, ci, 0], ag_cf[ai, ci, 1], ag_cn[ai, ci]):
                n += 1
        if not _compare(ag_q[qi, 1], np.int64(n), np.int64(d), ag_q[qi, 2] == 1, ag_qv[qi]):
            return -1, 0
    if ag_rule[ai, AR_Q1] > ag_rule[ai, AR_Q0]:  # name the first join whose quantified atoms hold, if any
        for e in range(e0, e1):
            if unsat[w, je_g[e]] != 0:
                continue
            whole = True
            for qi in range(ag_rule[ai, AR_Q0], ag_rule[ai, AR_Q1]):
                ci = ag_q[qi, 0]
                a = je_body[e, ci]
                if not _holds(lo[w, a], up[w, a], ag_cf[ai, ci, 0], ag_cf[ai, ci, 1], ag_cn[ai, ci]):
                    whole = False
                    break
            if whole:
                rep = je_g[e]
                break
    k = 0
    if ag_rule[ai, AR_FN] != FN_FIXED:
        for ci in range(ag_rule[ai, AR_NBODY]):
            for i in range(_candidates(w, ci, e0, e1, unsat, je_g, je_body, mark, stamp)):
                a = mark[1, i]
                if _holds(lo[w, a], up[w, a], ag_cf[ai, ci, 0], ag_cf[ai, ci, 1], ag_cn[ai, ci]):
                    g_l[k] = lo[w, a]
                    g_u[k] = up[w, a]
                    if ag_cn[ai, ci] & CLAUSE_CLOSED and lo[w, a] == 0.0 and up[w, a] == 1.0:
                        g_u[k] = 0.0  # a closed predicate's unset atom is read as [0,0]
                    g_w[k] = ag_cf[ai, ci, 2]
                    k += 1
    return rep, k


@kernel_jit
def agg_gather_requests(w, lo, up, unsat, hg_i, hg_ptr, je_g, je_body, ag_rule, ag_cf, ag_cn, ag_q, ag_qv, mark,
                        stamp, g_l, g_u, g_w, req_i, req_n, flat, ptr):
    """The inputs of the queued user annotation functions, for Python while the kernel waits: request i's
    atoms are flat[0..2, ptr[i]:ptr[i+1]] (lower, upper, weight)."""
    n = 0
    ptr[0] = 0
    for i in range(req_n[0]):
        _, k = _agg_eval(w, req_i[i, 0], lo, up, unsat, hg_i, hg_ptr, je_g, je_body, ag_rule, ag_cf, ag_cn,
                           ag_q, ag_qv, mark, stamp, g_l, g_u, g_w)
        for j in range(k):
            flat[0, n + j] = g_l[j]
            flat[1, n + j] = g_u[j]
            flat[2, n + j] = g_w[j]
        n += k
        ptr[i + 1] = n


@kernel_jit
def _agg_builtin(fn, g_l, g_u, g_w, k, out):
    """A built-in annotation function of k atoms into out[0], out[1] (engine/annotations.py has the same
    in Python, summing in the same order). False: no bound (no atoms, or weights summing to 0)."""
    if k == 0:
        return False
    if fn == FN_WEIGHTED_AVERAGE:
        sw = 0.0
        for i in range(k):
            sw += g_w[i]
        if sw == 0.0:
            return False
        sl = 0.0
        su = 0.0
        for i in range(k):
            sl += g_w[i] * g_l[i]
        for i in range(k):
            su += g_w[i] * g_u[i]
        out[0] = sl / sw
        out[1] = su / sw
        return True
    sl = 0.0
    su = 0.0
    mnl = g_l[0]
    mnu = g_u[0]
    mxl = g_l[0]
    mxu = g_u[0]
    for i in range(k):
        sl += g_l[i]
        su += g_u[i]
        mnl = min(mnl, g_l[i])
        mnu = min(mnu, g_u[i])
        mxl = max(mxl, g_l[i])
        mxu = max(mxu, g_u[i])
    if fn == FN_AVERAGE:
        out[0] = sl / k
        out[1] = su / k
    elif fn == FN_MIN:
        out[0] = mnl
        out[1] = mnu
    elif fn == FN_MAX:
        out[0] = mxl
        out[1] = mxu
    else:  # FN_AVERAGE_LOWER
        out[0] = sl / k
        out[1] = mxu
    return True


@kernel_jit
def _agg_fire(w, rule_f, hg_i, hg_ptr, je_g, je_body, ag_rule, ag_cf, ag_cn, ag_q, ag_qv, lo, up, unsat,
              mark, stamp, g_l, g_u, g_w, req_i, req_n, out, h):
    """Evaluate head group h for a firing: returns its grounding (-1: no firing) with its bound in out[0],
    out[1]; a group with a user function is queued in req_i instead (grounding -2)."""
    rep, k = _agg_eval(w, h, lo, up, unsat, hg_i, hg_ptr, je_g, je_body, ag_rule, ag_cf, ag_cn, ag_q, ag_qv,
                       mark, stamp, g_l, g_u, g_w)
    if rep < 0:
        return -1
    ai = hg_i[h, 0]
    fn = ag_rule[ai, AR_FN]
    if fn == FN_FIXED:
        out[0] = rule_f[ag_rule[ai, AR_RULE], 0]
        out[1] = rule_f[ag_rule[ai, AR_RULE], 1]
        return rep
    if k == 0:
        return -1
    if fn == FN_USER:
        n = req_n[0]
        req_i[n, 0] = h
        req_i[n, 1] = rep
        req_n[0] = n + 1
        return -2
    if not _agg_builtin(fn, g_l, g_u, g_w, k, out):
        return -1
    if ag_rule[ai, AR_HNEG] == 1:
        l = out[0]
        out[0] = 1.0 - out[1]
        out[1] = 1.0 - l
    return rep


@kernel_jit
def _agg_pass(w, rule_i, rule_f, inst, hg_i, hg_ptr, je_g, je_body, ag_rule, ag_cf, ag_cn, ag_q, ag_qv, lo, up,
              unsat, mark, stamp, g_l, g_u, g_w, req_i, req_n, out, slot_of, touched, n_touched, si, sf):
    """The firings of the aggregated Δt = 0 rules in this ordinary pass, as sources of the pass (every head
    group re-evaluated: exact, not incremental). User-function groups are queued in req_i."""
    for h in range(hg_i.shape[0]):
        ai = hg_i[h, 0]
        if ag_rule[ai, AR_KIND] != KIND_ORDINARY:
            continue
        g = _agg_fire(w, rule_f, hg_i, hg_ptr, je_g, je_body, ag_rule, ag_cf, ag_cn, ag_q, ag_qv,
                      lo, up, unsat, mark, stamp, g_l, g_u, g_w, req_i, req_n, out, h)
        if g >= 0:
            r = ag_rule[ai, AR_RULE]
            _add_source(np.int64(hg_i[h, 1]), out[0], out[1], rule_i[r, RULE_MODE] == MODE_OVERRIDE,
                        2 * KEY_STRIDE + inst[g, INST_RANK],
                        np.int64(CAUSE_RULE), np.int64(r), np.int64(g), rule_i[r, RULE_SET_STATIC] == 1,
                        slot_of, touched, n_touched, si, sf)


@kernel_jit
def _agg_user_sources(rule_i, inst, hg_i, ag_rule, req_i, req_f, req_n, slot_of, touched, n_touched, si, sf):
    """The queued user-function groups, with the bounds Python computed (req_f), as sources of the pass."""
    for i in range(req_n[0]):
        h = req_i[i, 0]
        g = req_i[i, 1]
        r = ag_rule[hg_i[h, 0], AR_RULE]
        _add_source(np.int64(hg_i[h, 1]), req_f[i, 0], req_f[i, 1], rule_i[r, RULE_MODE] == MODE_OVERRIDE,
                    2 * KEY_STRIDE + inst[g, INST_RANK],
                    np.int64(CAUSE_RULE), np.int64(r), np.int64(g), rule_i[r, RULE_SET_STATIC] == 1,
                    slot_of, touched, n_touched, si, sf)
    req_n[0] = 0


@kernel_jit
def _recount(w, g, lo, up, b_ptr, b_atom, b_flags, b_bnd, inst, kind_base, unsat, act, act_n, act_pos):
    """Count grounding g's unsatisfied binding clauses in world w from scratch; list it if active."""
    c = 0
    for e in range(b_ptr[g], b_ptr[g + 1]):
        a = b_atom[e]
        if not _holds(lo[w, a], up[w, a], b_bnd[e, 0], b_bnd[e, 1], b_flags[e]):
            c += 1
    unsat[w, g] = c
    act_pos[w, g] = -1
    if c == 0:
        k = inst[g, INST_KIND]
        p = act_n[w, k]
        act[w, kind_base[k] + p] = g
        act_pos[w, g] = p
        act_n[w, k] = p + 1


@kernel_jit
def recount_groundings(first, lo, up, b_ptr, b_atom, b_flags, b_bnd, inst, kind_base, unsat, act, act_n, act_pos):
    """Counts for groundings first.. in every world (used when the grounding table grows)."""
    for w in range(lo.shape[0]):
        for g in range(first, b_ptr.shape[0] - 1):
            _recount(w, g, lo, up, b_ptr, b_atom, b_flags, b_bnd, inst, kind_base, unsat, act, act_n, act_pos)


@kernel_jit
def recount_worlds(worlds, lo, up, b_ptr, b_atom, b_flags, b_bnd, inst, kind_base, unsat, act, act_n, act_pos):
    """Counts and active lists of the given worlds rebuilt from scratch (restore after growth)."""
    for i in range(worlds.shape[0]):
        w = worlds[i]
        for k in range(N_KINDS):
            act_n[w, k] = 0
        for g in range(b_ptr.shape[0] - 1):
            _recount(w, g, lo, up, b_ptr, b_atom, b_flags, b_bnd, inst, kind_base, unsat, act, act_n, act_pos)


@kernel_jit
def relayout_active(old_act, old_base, act, kind_base, act_n):
    """Copy every world's active lists into a table with new kind offsets (the grounding table grew)."""
    for w in range(act_n.shape[0]):
        for k in range(N_KINDS):
            for p in range(act_n[w, k]):
                act[w, kind_base[k] + p] = old_act[w, old_base[k] + p]


@kernel_jit
def gather_truth(bounds, atoms, value, out):
    """out[w, j] = (bounds[w, atoms[j]] == value): which atoms are [1,1] (bounds = lower, value 1) or
    [0,0] (bounds = upper, value 0) in each world."""
    for w in range(bounds.shape[0]):
        for j in range(atoms.shape[0]):
            out[w, j] = bounds[w, atoms[j]] == value
