"""The lanes kernel: one timestep of a whole batch of worlds for *crisp* programs, 64 worlds per machine word.

A crisp program only ever assigns [0,1], [1,1] or [0,0] (rule heads, facts, external facts; body clauses
may test any bound), so an atom's state in one world is one of three values, and its state in 64 worlds
is two words: the worlds where it is [1,1] (plane T) and where it is [0,0] (plane F); a third plane says
where it is static. A grounding's body holds in a word of worlds when the AND of its clauses' masks is
set. The worlds then step in lock-step:

- pass 0 and ordinary passes group their sources per atom with world masks;
- the immediate phase keeps one heap of candidate groundings for the whole batch. Popping the lowest
  rank applies it in every world where it is active and would change its head. That is exactly the
  per-world rule of docs/language.md ("apply the first active immediate grounding that would change
  its head"): the popped rank is the smallest candidate of every world, because every world's
  candidates are in the heap;
- a world leaves the fixpoint loop when its ordinary pass changes nothing.

Per-world work remains only where a world needs its own value: trace rows, the cause of each atom's last
change (lc [atom, world], tagged with the world's restore count wep[world], so that a restore need not
touch it), and statistics. Float bounds are not kept: in a crisp program the planes determine them.
The step is a small state machine (`ctl`): whenever the trace or the schedule may need more room than is
free, the kernel returns at a point where it can go on, core.py grows the buffer and calls again.

Same conventions as kernel.py: compiled once without reference counting, no allocation, everything
here in this one module (numba's cache does not see changes in other modules).
"""
from __future__ import annotations

import numpy as np
import llvmlite.ir as llvm_ir
from numba import njit, types
from numba.core import cgutils
from numba.core.extending import intrinsic

# The codes this kernel shares with kernel.py, written out here rather than imported: numba freezes
# globals into its cached machine code and does not notice a change in another module, so each kernel
# module stands alone; tests/test_lanes.py checks that both spell them alike (SHARED_CODES).
CAUSE_FACT, CAUSE_EXTERNAL, CAUSE_RULE, CAUSE_POLICY, CAUSE_RESET = 0, 1, 2, 3, 4
MODE_OVERRIDE = 1
POLICY_RESET_FREEZE, POLICY_KEEP_OLD, POLICY_TAKE_NEW, POLICY_HULL, POLICY_ABORT = 0, 1, 2, 3, 4
STATUS_OK, STATUS_INCONSISTENT, STATUS_NO_FIXPOINT, STATUS_IMMEDIATE_LIMIT = 0, 1, 2, 3
STATUS_NOT_SETTABLE, STATUS_TRACE_ROOM, STATUS_PEND_ROOM = 4, 5, 6
RULE_MODE, RULE_DELAY, RULE_SET_STATIC = 0, 1, 3
INST_RULE, INST_HEAD, INST_RANK, INST_KIND = 0, 1, 2, 3
KIND_IMMEDIATE, KIND_DELAYED, KIND_ORDINARY = 0, 1, 2
CFG_MODE, CFG_RESET, CFG_POLICY, CFG_MAX_PASSES, CFG_MAX_IMMEDIATE, CFG_T = 0, 1, 2, 3, 4, 5
STAT_FIRINGS, STAT_REDERIVATIONS, STAT_STATIC_IGNORED, STAT_CHANGES, STAT_PASSES = 0, 1, 2, 3, 4
STAT_WATCH_VISITS, STAT_CANDIDATES = 5, 6
E_WORLD, E_T, E_ATOM, E_OLD_KIND, E_OLD_ID, E_KIND, E_ID, E_INST, E_LAST_KIND, E_LAST_ID = range(10)
E_LAST_INST, E_DISAGREE = 10, 11
KEY_STRIDE = np.int64(1) << np.int64(40)
HEAP_SHIFT = np.int64(1) << np.int64(31)
HEAP_MASK = HEAP_SHIFT - np.int64(1)
SHARED_CODES = ("CAUSE_FACT", "CAUSE_EXTERNAL", "CAUSE_RULE", "CAUSE_POLICY", "CAUSE_RESET", "MODE_OVERRIDE",
                "POLICY_RESET_FREEZE", "POLICY_KEEP_OLD", "POLICY_TAKE_NEW", "POLICY_HULL", "POLICY_ABORT",
                "STATUS_OK", "STATUS_INCONSISTENT", "STATUS_NO_FIXPOINT", "STATUS_IMMEDIATE_LIMIT",
                "STATUS_NOT_SETTABLE", "STATUS_TRACE_ROOM", "STATUS_PEND_ROOM", "RULE_MODE", "RULE_DELAY",
                "RULE_SET_STATIC",
                "INST_RULE", "INST_HEAD", "INST_RANK", "INST_KIND", "KIND_IMMEDIATE", "KIND_DELAYED",
                "KIND_ORDINARY", "CFG_MODE", "CFG_RESET", "CFG_POLICY", "CFG_MAX_PASSES", "CFG_MAX_IMMEDIATE",
                "CFG_T", "STAT_FIRINGS", "STAT_REDERIVATIONS", "STAT_STATIC_IGNORED", "STAT_CHANGES",
                "STAT_PASSES", "STAT_WATCH_VISITS", "STAT_CANDIDATES", "E_WORLD", "E_T", "E_ATOM", "E_OLD_KIND",
                "E_OLD_ID", "E_KIND", "E_ID", "E_INST", "E_LAST_KIND", "E_LAST_ID", "E_LAST_INST", "E_DISAGREE",
                "KEY_STRIDE", "HEAP_SHIFT", "HEAP_MASK")

# how many groundings ahead of the one being updated a loop over a list of them asks for their gs lines
# (_prefetch)
PREFETCH_AHEAD = 8

# the three crisp values, as codes
V_U, V_T, V_F = 0, 1, 2  # [0,1], [1,1], [0,0]
# a clause's truth table: bit (1 << value) is set when the clause holds of that value
# planes of an atom's state, st[atom, plane, word]: [1,1], [0,0], static (its float bounds follow from
# the first two, so none are kept)
P_T, P_F, P_S = 0, 1, 2
N_PLANES = 3
# a last cause older than its world's last restore: it is the snapshot's (backend_lanes.py looks it up)
CAUSE_SNAPSHOT = -2
# a pass's grouped sources per touched atom, gm[slot, plane, word]: override sources setting T, F, U,
# intersection sources setting T, F, U, static sources
G_OT, G_OF, G_OU, G_IT, G_IF, G_IU, G_STAT = 0, 1, 2, 3, 4, 5, 6
N_GPLANES = 7
# ctl: where the step is (it can return to grow a buffer and go on from there); C_SETTLED: 1 when every
# world's state is the end of a step this kernel finished (no active immediate grounding would change its
# head), which the backend clears when it writes planes or counts itself (new groundings, restores);
# C_SCAN: this step's pass 0 looks at every active immediate grounding (the state was not settled)
C_PHASE, C_POS, C_PASS, C_SETTLED, C_SCAN = 0, 1, 2, 3, 4
N_CTL = 5
PH_START, PH_RESET, PH_PASS0, PH_GROUPS, PH_IMMEDIATE, PH_ORDINARY, PH_SCHEDULE, PH_DONE = 0, 1, 2, 3, 4, 5, 6, 7
# word scratch rows, ws[row, word]
W_RUN, W_CHANGED, W_C, W_OLDT, W_OLDF, W_UP, W_DOWN, W_ONE, W_TMP = 0, 1, 2, 3, 4, 5, 6, 7, 8
N_WSCRATCH = 9
# per-world scratch rows, pw[row, world]: sources of the current atom per world
PW_N, PW_PRIM, PW_LAST, PW_RULE = 0, 1, 2, 3
N_PW = 4

ZERO = np.uint64(0)
ONE = np.uint64(1)
ALL = np.uint64(0xFFFFFFFFFFFFFFFF)

# nogil: the shards of a batch step in threads (backend_lanes.py)
lanes_jit = njit(cache=True, _nrt=False, nogil=True)


@intrinsic
def _cttz(typingctx, x):
    """Index of the lowest set bit (llvm.cttz)."""
    def codegen(context, builder, signature, args):
        return builder.cttz(args[0], context.get_constant(types.boolean, False))
    return types.uint64(types.uint64), codegen


@intrinsic
def _prefetch(typingctx, arr, i):
    """Ask the CPU for the cache line of arr's flat element i (llvm.prefetch: read, keep it close). A
    watch list's groundings lie anywhere in gs (megabytes for a big program in 256 worlds): fetched
    one at a time, each waits for memory; asked for ahead, several are on their way at once."""
    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        i8p = llvm_ir.IntType(8).as_pointer()
        i32 = llvm_ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, llvm_ir.FunctionType(llvm_ir.VoidType(), [i8p, i32, i32, i32]),
                                            "llvm.prefetch.p0")
        builder.call(fn, [builder.bitcast(builder.gep(ary.data, [args[1]]), i8p), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()
    return types.void(arr, types.int64), codegen


@lanes_jit
def _holds(code, t, f):
    """The worlds of a word where a clause with truth table `code` holds, given planes T and F."""
    m = ZERO
    if code & 2:
        m |= t
    if code & 4:
        m |= f
    if code & 1:
        m |= ~(t | f)
    return m


@lanes_jit
def _count_add(gs, g, k, m):
    """Add one to the unsatisfied-clause count of grounding g in the worlds m of word k. Counts are
    bit-sliced: gs[g, k, 1 + p] holds bit p of every world's count (gs[g, k, 0] is the active mask)."""
    carry = m
    for p in range(1, gs.shape[2]):
        c = gs[g, k, p]
        gs[g, k, p] = c ^ carry
        carry &= c
        if carry == ZERO:
            break


@lanes_jit
def _count_sub(gs, g, k, m):
    """Take one from the count of grounding g in the worlds m of word k (every count there is >= 1)."""
    borrow = m
    for p in range(1, gs.shape[2]):
        c = gs[g, k, p]
        gs[g, k, p] = c ^ borrow
        borrow &= ~c
        if borrow == ZERO:
            break


@lanes_jit
def _count_zero(gs, g, k):
    """The worlds of word k where grounding g has no unsatisfied clause."""
    m = ZERO
    for p in range(1, gs.shape[2]):
        m |= gs[g, k, p]
    return ~m


@lanes_jit
def _lo(v):
    return 1.0 if v == V_T else 0.0


@lanes_jit
def _up(v):
    return 0.0 if v == V_F else 1.0


@lanes_jit
def _cause(lc, wep, a, w, kind, cid):
    """Atom a changed in world w by (kind, cid): its last cause, tagged with the world's restore count."""
    lc[a, w, 0] = kind
    lc[a, w, 1] = cid
    lc[a, w, 2] = wep[w]


@lanes_jit
def _old_cause(lc, wep, a, w, err):
    """The last cause of atom a in world w into err (an inconsistency's message); CAUSE_SNAPSHOT when it
    predates the world's last restore (backend_lanes.py then reads it from that snapshot)."""
    if lc[a, w, 2] == wep[w]:
        err[E_OLD_KIND] = lc[a, w, 0]
        err[E_OLD_ID] = lc[a, w, 1]
    else:
        err[E_OLD_KIND] = CAUSE_SNAPSHOT
        err[E_OLD_ID] = -1


@lanes_jit
def _list_add(g, inst, alist, alist_n, apos, kind_base):
    k = inst[g, INST_KIND]
    p = alist_n[k]
    alist[kind_base[k] + p] = g
    apos[g] = p
    alist_n[k] = p + 1


@lanes_jit
def _list_remove(g, inst, alist, alist_n, apos, kind_base):
    k = inst[g, INST_KIND]
    p = apos[g]
    last_i = alist_n[k] - 1
    last = alist[kind_base[k] + last_i]
    alist[kind_base[k] + p] = last
    apos[last] = p
    apos[g] = -1
    alist_n[k] = last_i


@lanes_jit
def _push(g, inst, heap, hn, in_heap):
    if in_heap[g]:
        return hn
    in_heap[g] = True
    key = np.int64(inst[g, INST_RANK]) * HEAP_SHIFT + g
    i = hn
    while i > 0:
        parent = (i - 1) >> 1
        pk = heap[parent]
        if pk <= key:
            break
        heap[i] = pk
        i = parent
    heap[i] = key
    return hn + 1


@lanes_jit
def _pop(heap, hn):
    top = heap[0]
    n = hn - 1
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


@lanes_jit
def _changes(g, k, st, inst, rule_i, rule_v):
    """The worlds of word k where immediate grounding g, applied now, could change its head (a superset:
    an inconsistency counts, whatever the policy). Only there is it made a candidate: elsewhere it can
    become one only when its head changes or it becomes active again, and both push it then."""
    a = inst[g, INST_HEAD]
    r = inst[g, INST_RULE]
    v = rule_v[r]
    t = st[a, P_T, k]
    f = st[a, P_F, k]
    if rule_i[r, RULE_SET_STATIC] == 1:
        m = ALL  # applying it freezes the head, a change of its own
    elif v == V_T:
        m = ~t
    elif v == V_F:
        m = ~f
    elif rule_i[r, RULE_MODE] == MODE_OVERRIDE:
        m = t | f
    else:
        m = ZERO
    return m & ~st[a, P_S, k]


@lanes_jit
def _watch(a, skip, st, valid, ws, wl, wc_ptr, wc_code, wc_gptr, wg, gs, inst, rule_i, rule_v, alist,
           alist_n, apos, kind_base, ih_ptr, ih_inst, heap, hn, in_heap, stats):
    """Atom a changed in the worlds ws[W_C] (its old planes in ws[W_OLDT], ws[W_OLDF]; st holds the new):
    update the counts and active masks of the groundings that read it, keep the active-anywhere lists, and make the
    immediate groundings that became active somewhere, or that set a there (but `skip`), candidates.
    Only the words where a clause flipped are visited (wl lists them). Returns the heap size."""
    nw = valid.shape[0]
    visits = 0
    for c in range(wc_ptr[a], wc_ptr[a + 1]):
        code = wc_code[c]
        n_flip = 0
        for k in range(nw):
            ck = ws[W_C, k]
            if ck == ZERO:
                continue
            was = _holds(code, ws[W_OLDT, k], ws[W_OLDF, k])
            now = _holds(code, st[a, P_T, k], st[a, P_F, k])
            u = ck & now & ~was
            d = ck & was & ~now
            if u | d:
                ws[W_UP, k] = u
                ws[W_DOWN, k] = d
                wl[n_flip] = k
                n_flip += 1
        if n_flip == 0:
            continue
        e1 = wc_gptr[c + 1]
        visits += e1 - wc_gptr[c]
        stride = np.int64(gs.shape[1] * gs.shape[2])  # one grounding's words
        first_word = wl[0] * gs.shape[2]
        last_word = wl[n_flip - 1] * gs.shape[2]
        for e in range(wc_gptr[c], e1):
            if e + PREFETCH_AHEAD < e1:
                ahead = np.int64(wg[e + PREFETCH_AHEAD]) * stride
                _prefetch(gs, ahead + first_word)
                _prefetch(gs, ahead + last_word)
            g = wg[e]
            emptied = False  # a word of the mask went to zero: is the grounding still active anywhere?
            filled = False  # a word went from zero: it is (now) active somewhere
            new_bits = False
            for j in range(n_flip):
                k = wl[j]
                old = gs[g, k, 0]
                d = ws[W_DOWN, k]
                if d != ZERO:
                    _count_add(gs, g, k, d)
                u = ws[W_UP, k]
                if u != ZERO:
                    _count_sub(gs, g, k, u)
                    new = _count_zero(gs, g, k) & valid[k]
                else:  # counts only went up: the worlds of d are inactive now, the others as they were
                    new = old & ~d
                if new == old:
                    continue
                gs[g, k, 0] = new
                if new & ~old and inst[g, INST_KIND] == KIND_IMMEDIATE:
                    if new & ~old & _changes(g, k, st, inst, rule_i, rule_v):
                        new_bits = True
                if old == ZERO:
                    filled = True
                elif new == ZERO:
                    emptied = True
            if filled or emptied:
                listed = apos[g] >= 0
                now_any = False
                for k in range(nw):
                    if gs[g, k, 0] != ZERO:
                        now_any = True
                        break
                if now_any and not listed:
                    _list_add(g, inst, alist, alist_n, apos, kind_base)
                elif listed and not now_any:
                    _list_remove(g, inst, alist, alist_n, apos, kind_base)
            if new_bits:
                hn = _push(g, inst, heap, hn, in_heap)
    stats[0, STAT_WATCH_VISITS] += visits
    # The immediate groundings that set a can change it only where a changed, is not static and is not
    # already their value: most heads are set by many groundings (one per cell, say) of one value, and a
    # change to that value leaves none of them anything to do. These masks and the active-anywhere list
    # (apos, compact) rule most of them out before their words of gs are read.
    to_t = ZERO  # the worlds where a changed and is not [1,1] now: a [1,1] setter may change it
    to_f = ZERO
    to_set = ZERO  # [1,1] or [0,0] there: an overriding [0,1] setter may change it
    to_any = ZERO  # not static there: a {set_static} setter may freeze it
    for k in range(nw):
        c = ws[W_C, k] & ~st[a, P_S, k]
        to_t |= c & ~st[a, P_T, k]
        to_f |= c & ~st[a, P_F, k]
        to_set |= c & (st[a, P_T, k] | st[a, P_F, k])
        to_any |= c
    if to_any == ZERO:
        return hn
    for i in range(ih_ptr[a], ih_ptr[a + 1]):
        g = ih_inst[i]
        if g == skip or in_heap[g] or apos[g] < 0:
            continue
        r = inst[g, INST_RULE]
        if rule_i[r, RULE_SET_STATIC] != 1:
            v = rule_v[r]
            if v == V_T:
                if to_t == ZERO:
                    continue
            elif v == V_F:
                if to_f == ZERO:
                    continue
            elif rule_i[r, RULE_MODE] != MODE_OVERRIDE or to_set == ZERO:
                continue
        for k in range(nw):
            if gs[g, k, 0] & ws[W_C, k] & _changes(g, k, st, inst, rule_i, rule_v):
                hn = _push(g, inst, heap, hn, in_heap)
                break
    return hn


@lanes_jit
def _row(w0, w, t, pass_no, a, ov, nv, kind, cid, g_src, nsrc, tmask, tri, trf, tr_n):
    """One trace row, if world w is traced (room was made before)."""
    if tmask[w >> 6] & (ONE << np.uint64(w & 63)):
        n = tr_n[0]
        tri[n, 0] = w0 + w
        tri[n, 1] = t
        tri[n, 2] = pass_no
        tri[n, 3] = a
        tri[n, 4] = kind
        tri[n, 5] = cid
        tri[n, 6] = g_src
        tri[n, 7] = nsrc
        trf[n, 0] = _lo(ov)
        trf[n, 1] = _up(ov)
        trf[n, 2] = _lo(nv)
        trf[n, 3] = _up(nv)
        tr_n[0] = n + 1


@lanes_jit
def _add_src(a, v, over, key, kind, cid, g_src, static, m, slot_of, touched, n_touched, gm, slot_src,
             src_i, src_m, src_n):
    """Add one source (value v, world mask m) for atom a to this pass's group of a.
    src_i[i] = (key, kind, id, grounding, value, next source of the same atom)."""
    s = slot_of[a]
    nw = m.shape[0]
    if s < 0:
        s = n_touched[0]
        n_touched[0] = s + 1
        slot_of[a] = s
        touched[s] = a
        for p in range(N_GPLANES):
            for k in range(nw):
                gm[s, p, k] = ZERO
        slot_src[s] = -1
    i = src_n[0]
    src_n[0] = i + 1
    src_i[i, 0] = key
    src_i[i, 1] = kind
    src_i[i, 2] = cid
    src_i[i, 3] = g_src
    src_i[i, 4] = v
    src_i[i, 5] = slot_src[s]
    slot_src[s] = i
    plane = (G_OT if over else G_IT) + (0 if v == V_T else (1 if v == V_F else 2))
    for k in range(nw):
        src_m[i, k] = m[k]
        gm[s, plane, k] |= m[k]
        if static:
            gm[s, G_STAT, k] |= m[k]


@lanes_jit
def _sort_small(a, n):
    """Shell sort of a[:n] (the same as kernel.py's: see the note on shared codes above)."""
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


@lanes_jit
def _apply_group(w0, s, a, t, pass_no, policy, valid, st, wep, lc, tmask, tri, trf, tr_n, stats, err, gm,
                 slot_src, src_i, src_m, pw, ws):
    """Resolve the group of atom a (scratch slot s) in every world it touches (docs/language.md,
    'Updating an atom') and write the per-world records. Leaves the changed worlds in ws[W_C] and the
    old planes in ws[W_OLDT/W_OLDF] for _watch. Returns a status."""
    nw = valid.shape[0]
    # per world: how many sources, the first (primary), the last, and the first rule source
    any_src = False
    for k in range(nw):
        m = ZERO
        for p in range(6):
            m |= gm[s, p, k]
        ws[W_TMP, k] = m
        while m != ZERO:
            w = k * 64 + np.int64(_cttz(m))
            m &= m - ONE
            pw[PW_N, w] = 0
            pw[PW_PRIM, w] = -1
            pw[PW_LAST, w] = -1
            pw[PW_RULE, w] = -1
            any_src = True
    if not any_src:
        return STATUS_OK
    i = slot_src[s]
    while i >= 0:
        key = src_i[i, 0]
        for k in range(nw):
            m = src_m[i, k]
            while m != ZERO:
                w = k * 64 + np.int64(_cttz(m))
                m &= m - ONE
                pw[PW_N, w] += 1
                p = pw[PW_PRIM, w]
                if p < 0 or key < src_i[p, 0]:
                    pw[PW_PRIM, w] = i
                p = pw[PW_LAST, w]
                if p < 0 or key >= src_i[p, 0]:
                    pw[PW_LAST, w] = i
                if src_i[i, 1] == CAUSE_RULE:
                    p = pw[PW_RULE, w]
                    if p < 0 or key < src_i[p, 0]:
                        pw[PW_RULE, w] = i
        i = src_i[i, 5]
    for k in range(nw):
        t_k = st[a, P_T, k]
        f_k = st[a, P_F, k]
        s_k = st[a, P_S, k]
        anyk = ws[W_TMP, k]
        eff = anyk & ~s_k
        ot, of_, ou = gm[s, G_OT, k], gm[s, G_OF, k], gm[s, G_OU, k]
        it, if_, iu = gm[s, G_IT, k], gm[s, G_IF, k], gm[s, G_IU, k]
        has_o = ot | of_ | ou
        empty_o = ot & of_
        mo_t = ot & ~of_
        mo_f = of_ & ~ot
        base_t = (has_o & mo_t) | (~has_o & t_k)
        base_f = (has_o & mo_f) | (~has_o & f_k)
        base_u = ~(base_t | base_f)
        empty_i = it & if_
        mi_t = it & ~if_
        mi_f = if_ & ~it
        r_t = (base_t & ~mi_f) | (base_u & mi_t)
        r_f = (base_f & ~mi_t) | (base_u & mi_f)
        inc = (empty_o | empty_i | (base_t & mi_f) | (base_f & mi_t)) & eff
        freeze = (gm[s, G_STAT, k]) & eff
        if inc != ZERO:
            if policy == POLICY_ABORT:
                w = k * 64 + np.int64(_cttz(inc))
                p = pw[PW_PRIM, w]
                q = pw[PW_LAST, w]
                err[E_WORLD] = w0 + w
                err[E_T] = t
                err[E_ATOM] = a
                _old_cause(lc, wep, a, w0 + w, err)
                err[E_KIND] = src_i[p, 1]
                err[E_ID] = src_i[p, 2]
                err[E_INST] = src_i[p, 3]
                err[E_LAST_KIND] = src_i[q, 1]
                err[E_LAST_ID] = src_i[q, 2]
                err[E_LAST_INST] = src_i[q, 3]
                bit = ONE << np.uint64(w & 63)
                err[E_DISAGREE] = 1 if (empty_o | empty_i | (has_o & ((mo_t & mi_f) | (mo_f & mi_t)))) & bit else 0
                return STATUS_INCONSISTENT
            if policy == POLICY_RESET_FREEZE:
                r_t &= ~inc
                r_f &= ~inc
                freeze |= inc
            elif policy == POLICY_KEEP_OLD:
                r_t = (r_t & ~inc) | (t_k & inc)
                r_f = (r_f & ~inc) | (f_k & inc)
            elif policy == POLICY_HULL:
                any_t = t_k | ot | it
                any_f = f_k | of_ | if_
                any_u = ~(t_k | f_k) | ou | iu
                h_t = any_t & ~any_f & ~any_u
                h_f = any_f & ~any_t & ~any_u
                r_t = (r_t & ~inc) | (h_t & inc)
                r_f = (r_f & ~inc) | (h_f & inc)
            elif policy == POLICY_TAKE_NEW:
                # the incoming sources alone (Mo ∩ Mi) where they agree, else the last source's value
                mo_u = ~(mo_t | mo_f)
                n_t = (mo_t & ~mi_f) | (mo_u & mi_t)
                n_f = (mo_f & ~mi_t) | (mo_u & mi_f)
                ok = ~(empty_o | empty_i | (mo_t & mi_f) | (mo_f & mi_t))
                r_t = (r_t & ~inc) | (n_t & inc & ok)
                r_f = (r_f & ~inc) | (n_f & inc & ok)
                m = inc & ~ok
                while m != ZERO:
                    b = _cttz(m)
                    m &= m - ONE
                    v = src_i[pw[PW_LAST, k * 64 + np.int64(b)], 4]
                    bit = ONE << b
                    if v == V_T:
                        r_t |= bit
                    elif v == V_F:
                        r_f |= bit
        c = eff & ((r_t ^ t_k) | (r_f ^ f_k))
        ws[W_C, k] = c
        ws[W_OLDT, k] = t_k
        ws[W_OLDF, k] = f_k
        st[a, P_T, k] = (t_k & ~c) | (r_t & c)
        st[a, P_F, k] = (f_k & ~c) | (r_f & c)
        # per world: statistics, and for the changed worlds the row, bounds and cause
        m = anyk
        while m != ZERO:
            b = _cttz(m)
            m &= m - ONE
            w = k * 64 + np.int64(b)
            bit = ONE << b
            p = pw[PW_PRIM, w]
            kind = src_i[p, 1]
            nsrc = pw[PW_N, w]
            if kind == CAUSE_RULE:
                stats[w, STAT_FIRINGS] += nsrc
            if s_k & bit:
                stats[w, STAT_STATIC_IGNORED] += nsrc
                continue
            if c & bit:
                ov = V_T if t_k & bit else (V_F if f_k & bit else V_U)
                nv = V_T if r_t & bit else (V_F if r_f & bit else V_U)
                stats[w, STAT_CHANGES] += 1
                if inc & bit:
                    r = pw[PW_RULE, w]
                    _cause(lc, wep, a, w0 + w, CAUSE_POLICY, policy)
                    _row(w0, w, t, pass_no, a, ov, nv, CAUSE_POLICY, policy, src_i[r, 3] if r >= 0 else -1, nsrc,
                         tmask, tri, trf, tr_n)
                else:
                    _cause(lc, wep, a, w0 + w, kind, src_i[p, 2])
                    _row(w0, w, t, pass_no, a, ov, nv, kind, src_i[p, 2], src_i[p, 3], nsrc, tmask, tri, trf, tr_n)
            elif kind == CAUSE_RULE:
                stats[w, STAT_REDERIVATIONS] += nsrc
        st[a, P_S, k] = s_k | freeze
    return STATUS_OK


@lanes_jit
def _apply_immediate(w0, g, t, pass_no, policy, max_immediate, rule_i, rule_v, inst, valid, st, wep, lc, tmask,
                     tri, trf, tr_n, stats, err, n_imm, ws, wl, wc_ptr, wc_code, wc_gptr, wg, gs,
                      alist, alist_n, apos, kind_base, ih_ptr, ih_inst, heap, hn, in_heap):
    """Apply immediate grounding g in every world where it is active and would change its head.
    Returns (status, heap size)."""
    nw = valid.shape[0]
    a = inst[g, INST_HEAD]
    r = inst[g, INST_RULE]
    v = rule_v[r]
    over = rule_i[r, RULE_MODE] == MODE_OVERRIDE
    set_static = rule_i[r, RULE_SET_STATIC] == 1
    any_c = False
    any_inc = False
    any_fz = False
    for k in range(nw):
        m = gs[g, k, 0] & ~st[a, P_S, k]
        # {set_static}: it applies wherever it is active and the head is not static yet
        ws[W_ONE, k] = m if set_static else ZERO
        if set_static and m != ZERO:
            any_fz = True
        t_k = st[a, P_T, k]
        f_k = st[a, P_F, k]
        if over:
            r_t = ALL if v == V_T else ZERO
            r_f = ALL if v == V_F else ZERO
            inc = ZERO
        elif v == V_U:
            r_t, r_f, inc = t_k, f_k, ZERO
        elif v == V_T:
            r_t, r_f, inc = ~f_k, ZERO, f_k
        else:
            r_t, r_f, inc = ZERO, ~t_k, t_k
        inc &= m
        if inc != ZERO:
            if policy == POLICY_KEEP_OLD:
                r_t = (r_t & ~inc) | (t_k & inc)
                r_f = (r_f & ~inc) | (f_k & inc)
            elif policy == POLICY_TAKE_NEW:
                r_t = (r_t & ~inc) | (inc if v == V_T else ZERO)
                r_f = (r_f & ~inc) | (inc if v == V_F else ZERO)
            else:  # reset_freeze and hull (two disjoint crisp values span [0,1]); abort stops below
                r_t &= ~inc
                r_f &= ~inc
        c = m & ((r_t ^ t_k) | (r_f ^ f_k))
        if policy == POLICY_ABORT:
            c |= inc
        ws[W_C, k] = c
        ws[W_OLDT, k] = t_k
        ws[W_OLDF, k] = f_k
        ws[W_UP, k] = r_t  # the new planes until _watch reuses these rows
        ws[W_DOWN, k] = r_f
        ws[W_TMP, k] = inc
        if c != ZERO:
            any_c = True
        if inc & c:
            any_inc = True
    stats[0, STAT_CANDIDATES] += 1
    if not any_c and not any_fz:
        return STATUS_OK, hn
    # per world, in world order: the immediate limit, then an inconsistency under abort
    for k in range(nw):
        m = ws[W_C, k] | ws[W_ONE, k]
        while m != ZERO:
            b = _cttz(m)
            m &= m - ONE
            w = k * 64 + np.int64(b)
            n_imm[w] += 1
            stats[w, STAT_FIRINGS] += 1
            if n_imm[w] > max_immediate:
                err[E_WORLD] = w0 + w
                err[E_T] = t
                err[E_ATOM] = a
                return STATUS_IMMEDIATE_LIMIT, hn
            if policy == POLICY_ABORT and ws[W_TMP, k] & (ONE << b):
                err[E_WORLD] = w0 + w
                err[E_T] = t
                err[E_ATOM] = a
                _old_cause(lc, wep, a, w0 + w, err)
                err[E_KIND] = CAUSE_RULE
                err[E_ID] = r
                err[E_INST] = g
                err[E_LAST_KIND] = CAUSE_RULE
                err[E_LAST_ID] = r
                err[E_LAST_INST] = g
                err[E_DISAGREE] = 0
                return STATUS_INCONSISTENT, hn
            if not ws[W_C, k] & (ONE << b):  # a {set_static} firing that only freezes the head
                stats[w, STAT_REDERIVATIONS] += 1
    for k in range(nw):
        c = ws[W_C, k]
        st[a, P_S, k] |= ws[W_ONE, k]  # {set_static}: frozen after the update (the new planes are set below)
        if c == ZERO:
            continue
        t_k = ws[W_OLDT, k]
        f_k = ws[W_OLDF, k]
        r_t = ws[W_UP, k]
        r_f = ws[W_DOWN, k]
        inc = ws[W_TMP, k]
        st[a, P_T, k] = (t_k & ~c) | (r_t & c)
        st[a, P_F, k] = (f_k & ~c) | (r_f & c)
        if policy == POLICY_RESET_FREEZE:
            st[a, P_S, k] |= inc & c
        m = c
        while m != ZERO:
            b = _cttz(m)
            m &= m - ONE
            w = k * 64 + np.int64(b)
            bit = ONE << b
            ov = V_T if t_k & bit else (V_F if f_k & bit else V_U)
            nv = V_T if r_t & bit else (V_F if r_f & bit else V_U)
            stats[w, STAT_CHANGES] += 1
            if inc & bit:
                _cause(lc, wep, a, w0 + w, CAUSE_POLICY, policy)
                _row(w0, w, t, pass_no, a, ov, nv, CAUSE_POLICY, policy, g, 1, tmask, tri, trf, tr_n)
            else:
                _cause(lc, wep, a, w0 + w, CAUSE_RULE, r)
                _row(w0, w, t, pass_no, a, ov, nv, CAUSE_RULE, r, g, 1, tmask, tri, trf, tr_n)
    hn = _watch(a, -1 if any_inc else g, st, valid, ws, wl, wc_ptr, wc_code, wc_gptr, wg, gs,
                inst, rule_i, rule_v, alist, alist_n, apos, kind_base, ih_ptr, ih_inst, heap, hn, in_heap, stats)
    return STATUS_OK, hn


@lanes_jit
def _reset_atom(w0, a, t, valid, st, wep, lc, tmask, tri, trf, tr_n, stats, ws):
    """`%timesteps reset` for one atom: back to [0,1] where it is set and not static. Leaves the changed
    worlds in ws[W_C]; returns whether there are any."""
    any_c = False
    for k in range(valid.shape[0]):
        t_k = st[a, P_T, k]
        f_k = st[a, P_F, k]
        c = (t_k | f_k) & ~st[a, P_S, k] & valid[k]
        ws[W_C, k] = c
        ws[W_OLDT, k] = t_k
        ws[W_OLDF, k] = f_k
        if c == ZERO:
            continue
        any_c = True
        st[a, P_T, k] = t_k & ~c
        st[a, P_F, k] = f_k & ~c
        m = c
        while m != ZERO:
            b = _cttz(m)
            m &= m - ONE
            w = k * 64 + np.int64(b)
            ov = V_T if t_k & (ONE << b) else V_F
            _cause(lc, wep, a, w0 + w, CAUSE_RESET, -1)
            stats[w, STAT_CHANGES] += 1
            _row(w0, w, t, 0, a, ov, V_U, CAUSE_RESET, -1, -1, 0, tmask, tri, trf, tr_n)
    return any_c


@lanes_jit
def step_lanes(cfg, w0, ctl, rule_i, rule_v, inst, kind_base, wc_ptr, wc_code, wc_gptr, wg,
               ih_ptr, ih_inst, fact_i, fact_v, fact_order, ext_ptr, ext_i, ext_v, settable, valid, tmask,
               st, wep, lc, gs, alist, alist_n, apos, pend_due, pend_g, pend_m, pend_n,
               tri, trf, tr_n, stats, err, slot_of, touched, n_touched, gm, slot_src, src_i, src_m, src_n,
               heap, hn_box, in_heap, n_imm, pw, ws, wl):
    """Go on with timestep cfg[CFG_T] of every world from where ctl says (PH_START: from the beginning).
    Returns STATUS_OK when the step is done, STATUS_TRACE_ROOM / STATUS_PEND_ROOM when a buffer must
    grow first (then call again), or an error status."""
    t = cfg[CFG_T]
    fact_override = cfg[CFG_MODE] == MODE_OVERRIDE
    policy = cfg[CFG_POLICY]
    max_passes = cfg[CFG_MAX_PASSES]
    max_immediate = cfg[CFG_MAX_IMMEDIATE]
    n_worlds = n_imm.shape[0]  # this call's worlds: w0 .. w0 + n_worlds - 1 of wep, lc and rows
    nw = valid.shape[0]
    n_atoms = st.shape[0]
    stride = np.int64(gs.shape[1] * gs.shape[2])  # one grounding's words of gs (_prefetch)
    hn = hn_box[0]
    while True:
        phase = ctl[C_PHASE]
        if phase == PH_START:
            for e in range(ext_ptr[0], ext_ptr[n_worlds]):  # checked before anything changes
                if not settable[ext_i[e, 0]]:
                    err[E_ATOM] = ext_i[e, 0]
                    return STATUS_NOT_SETTABLE
            for k in range(nw):
                ws[W_RUN, k] = valid[k]
                ws[W_CHANGED, k] = ZERO
            for w in range(n_worlds):
                n_imm[w] = 0
            hn = 0
            ctl[C_POS] = 0
            ctl[C_PASS] = 0
            ctl[C_SCAN] = 1 - ctl[C_SETTLED]
            ctl[C_SETTLED] = 0  # until this step is done (an error leaves it unsettled)
            ctl[C_PHASE] = PH_RESET if cfg[CFG_RESET] == 1 and t > 0 else PH_PASS0
        elif phase == PH_RESET:
            for a in range(ctl[C_POS], n_atoms):
                if tri.shape[0] - tr_n[0] < n_worlds:
                    ctl[C_POS] = a
                    hn_box[0] = hn
                    return STATUS_TRACE_ROOM
                if _reset_atom(w0, a, t, valid, st, wep, lc, tmask, tri, trf, tr_n, stats, ws):
                    hn = _watch(a, -1, st, valid, ws, wl, wc_ptr, wc_code, wc_gptr, wg, gs,
                                inst, rule_i, rule_v, alist, alist_n, apos, kind_base, ih_ptr, ih_inst, heap, hn, in_heap,
                                stats)
            ctl[C_PHASE] = PH_PASS0
        elif phase == PH_PASS0:
            # program facts in their window, external facts, firings scheduled for t
            for i in range(fact_order.shape[0]):
                f = fact_order[i]
                if fact_i[f, 2] < t:
                    break
                if fact_i[f, 1] <= t:
                    _add_src(fact_i[f, 0], fact_v[f], fact_override, np.int64(f), CAUSE_FACT, f, -1,
                             fact_i[f, 3] == 1, valid, slot_of, touched, n_touched, gm, slot_src, src_i, src_m,
                             src_n)
            for w in range(n_worlds):
                if ext_ptr[w] == ext_ptr[w + 1]:
                    continue
                for k in range(nw):
                    ws[W_ONE, k] = ZERO
                ws[W_ONE, w >> 6] = ONE << np.uint64(w & 63)
                for e in range(ext_ptr[w], ext_ptr[w + 1]):
                    _add_src(ext_i[e, 0], ext_v[e], fact_override, KEY_STRIDE + ext_i[e, 2], CAUSE_EXTERNAL,
                             ext_i[e, 2], -1, ext_i[e, 1] == 1, ws[W_ONE], slot_of, touched, n_touched, gm,
                             slot_src, src_i, src_m, src_n)
            kept = 0
            for p in range(pend_n[0]):
                g = pend_g[p]
                if pend_due[p] == t:
                    r = inst[g, INST_RULE]
                    _add_src(inst[g, INST_HEAD], rule_v[r], rule_i[r, RULE_MODE] == MODE_OVERRIDE,
                             2 * KEY_STRIDE + inst[g, INST_RANK], CAUSE_RULE, r, g, rule_i[r, RULE_SET_STATIC] == 1, pend_m[p], slot_of,
                             touched, n_touched, gm, slot_src, src_i, src_m, src_n)
                else:
                    pend_due[kept] = pend_due[p]
                    pend_g[kept] = g
                    for k in range(nw):
                        pend_m[kept, k] = pend_m[p, k]
                    kept += 1
            pend_n[0] = kept
            _sort_small(touched, n_touched[0])
            ctl[C_POS] = 0
            ctl[C_PHASE] = PH_GROUPS
        elif phase == PH_GROUPS:
            pass_no = ctl[C_PASS]
            n = n_touched[0]
            for i in range(ctl[C_POS], n):
                if tri.shape[0] - tr_n[0] < n_worlds:
                    ctl[C_POS] = i
                    hn_box[0] = hn
                    return STATUS_TRACE_ROOM
                a = touched[i]
                status = _apply_group(w0, slot_of[a], a, t, pass_no, policy, valid, st, wep, lc, tmask, tri, trf,
                                      tr_n, stats, err, gm, slot_src, src_i, src_m, pw, ws)
                if status != STATUS_OK:
                    return status
                slot_of[a] = -1
                any_c = False
                for k in range(nw):
                    ws[W_CHANGED, k] |= ws[W_C, k]
                    if ws[W_C, k] != ZERO:
                        any_c = True
                if any_c:
                    hn = _watch(a, -1, st, valid, ws, wl, wc_ptr, wc_code, wc_gptr, wg, gs,
                                inst, rule_i, rule_v, alist, alist_n, apos, kind_base, ih_ptr, ih_inst, heap, hn, in_heap,
                                stats)
            n_touched[0] = 0
            src_n[0] = 0
            if pass_no == 0:
                # every immediate grounding active somewhere that could change its head is a candidate of
                # the first immediate phase; after that, groundings become candidates when they become
                # active or their head changes. After a step this kernel finished no active one could
                # (the immediate phase ran until none would), and pass 0's changes pushed those that now
                # can (_watch): only a state the backend wrote needs them all looked at
                base = kind_base[KIND_IMMEDIATE]
                n_imm_active = alist_n[KIND_IMMEDIATE] if ctl[C_SCAN] == 1 else 0
                for i in range(n_imm_active):
                    if i + PREFETCH_AHEAD < n_imm_active:
                        _prefetch(gs, np.int64(alist[base + i + PREFETCH_AHEAD]) * stride)
                    g = alist[base + i]
                    for k in range(nw):
                        if gs[g, k, 0] & _changes(g, k, st, inst, rule_i, rule_v):
                            hn = _push(g, inst, heap, hn, in_heap)
                            break
                ctl[C_PASS] = 1
                ctl[C_PHASE] = PH_IMMEDIATE
            else:
                more = False
                for k in range(nw):
                    m = ws[W_RUN, k]
                    while m != ZERO:
                        w = k * 64 + np.int64(_cttz(m))
                        m &= m - ONE
                        stats[w, STAT_PASSES] += 1
                    ws[W_RUN, k] = ws[W_CHANGED, k]
                    if ws[W_CHANGED, k] != ZERO:
                        more = True
                if not more:
                    ctl[C_PHASE] = PH_SCHEDULE
                else:
                    ctl[C_PASS] = pass_no + 1
                    if pass_no + 1 > max_passes:
                        for k in range(nw):
                            if ws[W_RUN, k] != ZERO:
                                err[E_WORLD] = w0 + k * 64 + np.int64(_cttz(ws[W_RUN, k]))
                                break
                        err[E_T] = t
                        err[E_ATOM] = -1
                        return STATUS_NO_FIXPOINT
                    ctl[C_PHASE] = PH_IMMEDIATE
            for k in range(nw):
                ws[W_CHANGED, k] = ZERO
        elif phase == PH_IMMEDIATE:
            pass_no = ctl[C_PASS]
            while hn > 0:
                if tri.shape[0] - tr_n[0] < n_worlds:
                    hn_box[0] = hn
                    return STATUS_TRACE_ROOM
                key = _pop(heap, hn)
                hn -= 1
                g = key & HEAP_MASK
                in_heap[g] = False
                if hn > 0:  # most often the next one applied (unless this one's changes push a lower rank)
                    _prefetch(gs, (heap[0] & HEAP_MASK) * stride)
                status, hn = _apply_immediate(w0, g, t, pass_no, policy, max_immediate, rule_i, rule_v, inst, valid,
                                              st, wep, lc, tmask, tri, trf, tr_n, stats, err, n_imm, ws, wl, wc_ptr,
                                              wc_code, wc_gptr, wg, gs, alist, alist_n,
                                              apos, kind_base, ih_ptr, ih_inst, heap, hn, in_heap)
                if status != STATUS_OK:
                    return status
            ctl[C_PHASE] = PH_ORDINARY
        elif phase == PH_ORDINARY:
            # every active Δt = 0 grounding fires in the worlds still looking for their fixpoint
            base = kind_base[KIND_ORDINARY]
            for i in range(alist_n[KIND_ORDINARY]):
                g = alist[base + i]
                m_any = False
                for k in range(nw):
                    ws[W_ONE, k] = gs[g, k, 0] & ws[W_RUN, k]
                    if ws[W_ONE, k] != ZERO:
                        m_any = True
                if m_any:
                    r = inst[g, INST_RULE]
                    _add_src(inst[g, INST_HEAD], rule_v[r], rule_i[r, RULE_MODE] == MODE_OVERRIDE,
                             2 * KEY_STRIDE + inst[g, INST_RANK], CAUSE_RULE, r, g, rule_i[r, RULE_SET_STATIC] == 1, ws[W_ONE], slot_of,
                             touched, n_touched, gm, slot_src, src_i, src_m, src_n)
            _sort_small(touched, n_touched[0])
            ctl[C_POS] = 0
            ctl[C_PHASE] = PH_GROUPS
        elif phase == PH_SCHEDULE:
            # delayed rules read the final interpretation of t and schedule their heads
            n_del = alist_n[KIND_DELAYED]
            n = pend_n[0]
            if n + n_del > pend_g.shape[0]:
                hn_box[0] = hn
                return STATUS_PEND_ROOM
            base = kind_base[KIND_DELAYED]
            for i in range(n_del):
                g = alist[base + i]
                pend_due[n] = t + rule_i[inst[g, INST_RULE], RULE_DELAY]
                pend_g[n] = g
                for k in range(nw):
                    pend_m[n, k] = gs[g, k, 0]
                n += 1
            pend_n[0] = n
            ctl[C_PHASE] = PH_DONE
            ctl[C_SETTLED] = 1
            hn_box[0] = 0
            return STATUS_OK
        else:
            return STATUS_OK


@lanes_jit
def fill_counts(first, valid, st, b_ptr, b_atom, b_code, gs, inst, alist, alist_n, apos, kind_base):
    """Counts and active masks of groundings first.. from the current state; the active-anywhere lists
    rebuilt."""
    nw = valid.shape[0]
    for g in range(first, gs.shape[0]):
        for k in range(nw):
            for p in range(gs.shape[2]):
                gs[g, k, p] = ZERO
            for e in range(b_ptr[g], b_ptr[g + 1]):
                a = b_atom[e]
                _count_add(gs, g, k, ~_holds(b_code[e], st[a, P_T, k], st[a, P_F, k]) & valid[k])
            gs[g, k, 0] = _count_zero(gs, g, k) & valid[k]
    rebuild_lists(gs, inst, alist, alist_n, apos, kind_base)


@lanes_jit
def rebuild_lists(gs, inst, alist, alist_n, apos, kind_base):
    for k in range(alist_n.shape[0]):
        alist_n[k] = 0
    for g in range(gs.shape[0]):
        apos[g] = -1
        for k in range(gs.shape[1]):
            if gs[g, k, 0] != ZERO:
                _list_add(g, inst, alist, alist_n, apos, kind_base)
                break


@lanes_jit
def _relist(g, gs, inst, alist, alist_n, apos, kind_base):
    """A restore turned grounding g's active mask to or from zero in a word: g joins or leaves its kind's
    active-anywhere list as it is now active in some world or in none. g is an int64 (one signature)."""
    now_any = False
    for k in range(gs.shape[1]):
        if gs[g, k, 0] != ZERO:
            now_any = True
            break
    listed = apos[g] >= 0
    if now_any and not listed:
        _list_add(g, inst, alist, alist_n, apos, kind_base)
    elif listed and not now_any:
        _list_remove(g, inst, alist, alist_n, apos, kind_base)


@lanes_jit
def _restore_lanes(wmask, snap_st, snap_gs, st, gs, inst, alist, alist_n, apos, kind_base):
    """The worlds of wmask take their planes, counts and active masks from the snapshot (atoms and
    groundings the snapshot has); the active-anywhere lists follow. Words without such worlds are
    not touched."""
    nw = wmask.shape[0]
    for a in range(snap_st.shape[0]):
        for p in range(N_PLANES):
            for k in range(nw):
                m = wmask[k]
                if m != ZERO:
                    st[a, p, k] = (st[a, p, k] & ~m) | (snap_st[a, p, k] & m)
    for g in range(snap_gs.shape[0]):
        flipped = False  # some word's active mask went to or from zero
        for k in range(nw):
            m = wmask[k]
            if m == ZERO:
                continue
            old = gs[g, k, 0]
            for p in range(gs.shape[2]):
                gs[g, k, p] = (gs[g, k, p] & ~m) | (snap_gs[g, k, p] & m)
            if (old == ZERO) != (gs[g, k, 0] == ZERO):
                flipped = True
        if flipped:
            _relist(g, gs, inst, alist, alist_n, apos, kind_base)


@lanes_jit
def restore_worlds(local, shift, snap_st, snap_gs, snap_due, snap_g, snap_m, st, gs, inst, alist, alist_n, apos,
                   kind_base, pend_due, pend_g, pend_m, pend_n, wmask):
    """Worlds `local` (of this shard) go back to a snapshot: planes, counts and active masks; atoms
    interned since unset; their scheduled firings dropped and the snapshot's taken, `shift` steps later.
    The schedule must have room for its rows plus the snapshot's. wmask [words] is scratch (left holding
    the worlds' mask)."""
    nw = wmask.shape[0]
    for k in range(nw):
        wmask[k] = ZERO
    for i in range(local.shape[0]):
        wmask[local[i] >> 6] |= ONE << np.uint64(local[i] & 63)
    _restore_lanes(wmask, snap_st, snap_gs, st, gs, inst, alist, alist_n, apos, kind_base)
    for a in range(snap_st.shape[0], st.shape[0]):
        for p in range(N_PLANES):
            for k in range(nw):
                st[a, p, k] &= ~wmask[k]
    j = 0
    for i in range(pend_n[0]):  # keep the other worlds' firings, in order
        left = False
        for k in range(nw):
            pend_m[i, k] &= ~wmask[k]
            if pend_m[i, k] != ZERO:
                left = True
        if left:
            pend_due[j] = pend_due[i]
            pend_g[j] = pend_g[i]
            for k in range(nw):
                pend_m[j, k] = pend_m[i, k]
            j += 1
    for i in range(snap_g.shape[0]):
        theirs = False
        for k in range(nw):
            m = snap_m[i, k] & wmask[k]
            pend_m[j, k] = m
            if m != ZERO:
                theirs = True
        if theirs:
            pend_due[j] = snap_due[i] + shift
            pend_g[j] = snap_g[i]
            j += 1
    pend_n[0] = j


@lanes_jit
def restore_worlds_from(targets, sources, shift, snap_st, snap_gs, snap_due, snap_g, snap_m, st, gs, inst, alist,
                        alist_n, apos, kind_base, pend_due, pend_g, pend_m, pend_n):
    """Worlds `targets` (of this shard) take the state of the snapshot part's worlds `sources` (local to
    that part), one by one: planes, counts and active masks bit by bit; atoms interned since unset; their
    scheduled firings dropped and the source world's taken, `shift` steps later, as rows of their own.
    The schedule must have room for its rows plus len(targets) times the snapshot's."""
    nw = st.shape[2]
    for i in range(targets.shape[0]):
        t, s = targets[i], sources[i]
        tk, tbit = t >> 6, ONE << np.uint64(t & 63)
        sk, sshift = s >> 6, np.uint64(s & 63)
        tshift = np.uint64(t & 63)
        for a in range(st.shape[0]):
            for p in range(N_PLANES):
                bit = ((snap_st[a, p, sk] >> sshift) & ONE) if a < snap_st.shape[0] else ZERO
                st[a, p, tk] = (st[a, p, tk] & ~tbit) | (bit << tshift)
        for g in range(snap_gs.shape[0]):
            old = gs[g, tk, 0]
            for p in range(gs.shape[2]):
                bit = (snap_gs[g, sk, p] >> sshift) & ONE
                gs[g, tk, p] = (gs[g, tk, p] & ~tbit) | (bit << tshift)
            if (old == ZERO) != (gs[g, tk, 0] == ZERO):
                _relist(g, gs, inst, alist, alist_n, apos, kind_base)
        j = 0
        for r in range(pend_n[0]):  # keep the other worlds' firings, in order
            pend_m[r, tk] &= ~tbit
            left = False
            for k in range(nw):
                if pend_m[r, k] != ZERO:
                    left = True
            if left:
                pend_due[j] = pend_due[r]
                pend_g[j] = pend_g[r]
                for k in range(nw):
                    pend_m[j, k] = pend_m[r, k]
                j += 1
        for r in range(snap_g.shape[0]):
            if (snap_m[r, sk] >> sshift) & ONE:
                for k in range(nw):
                    pend_m[j, k] = ZERO
                pend_m[j, tk] = tbit
                pend_due[j] = snap_due[r] + shift
                pend_g[j] = snap_g[r]
                j += 1
        pend_n[0] = j


@lanes_jit
def plane_truth(st, plane, atoms, w0, n_worlds, out):
    """Sets out[w0 + w, j] where bit w of plane `plane` of atom atoms[j] is set, for w < n_worlds ([1,1]:
    P_T, [0,0]: P_F). `out` comes zeroed: only set bits are visited (most atoms hold in few worlds)."""
    for j in range(atoms.shape[0]):
        a = atoms[j]
        for k in range(st.shape[2]):
            m = st[a, plane, k]
            while m != ZERO:
                w = k * 64 + np.int64(_cttz(m))
                m &= m - ONE
                if w < n_worlds:
                    out[w0 + w, j] = True
