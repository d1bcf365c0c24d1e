"""The compiled step kernel: one call computes one timestep for every world of a batch.

Everything here works on flat integer/float arrays, so one compiled kernel serves every rule program:
a new rule file changes the arrays, never the code (no recompile). All njit code lives in this one
module because numba's disk cache does not notice changes to callees in other modules.

How rules are evaluated: the grounder (grounding.py) enumerates, once, every rule grounding that could
ever fire. Each grounding keeps a count of its body clauses that do not hold (`unsat`); a change of an
atom's interval updates the counts of the groundings that watch that atom, and groundings whose count
reaches zero sit in the world's `active` list. A timestep then costs work proportional to the changes
and the active groundings, not to the size of the program.
"""
from __future__ import annotations

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

# column layout of the packed arrays
RULE_MODE, RULE_DELAY, RULE_IMMEDIATE = 0, 1, 2
INST_RULE, INST_HEAD, INST_RANK = 0, 1, 2
# per-grounding kind bits (inst_kind, uint8[G]): its rule is immediate / delayed (Δt > 0) / ordinary Δt = 0.
# A small dense array, so that the scans of the active list need not read inst_i and rule_i per grounding.
KIND_IMMEDIATE, KIND_DELAYED, KIND_ORDINARY = 1, 2, 4
CFG_MODE, CFG_RESET, CFG_POLICY, CFG_MAX_PASSES, CFG_MAX_IMMEDIATE, CFG_T = 0, 1, 2, 3, 4, 5
# trace int columns: world, t, pass_no, atom, cause_kind, cause_id, grounding, n_sources
TRACE_INT_COLUMNS = 8
# trace float columns: old_lower, old_upper, new_lower, new_upper
TRACE_FLOAT_COLUMNS = 4
# stats columns
STAT_FIRINGS, STAT_REDERIVATIONS, STAT_STATIC_IGNORED, STAT_CHANGES, STAT_PASSES = 0, 1, 2, 3, 4
STAT_WATCH_VISITS, STAT_CANDIDATES = 5, 6  # work counters: clause checks after changes, heap pops
N_STATS = 7

# grouping scratch: flags in S_FLAGS
F_OVERRIDE, F_INTERSECT, F_EMPTY_O, F_EMPTY_I, F_STATIC, F_TOUCHED = 1, 2, 4, 8, 16, 32
S_FLAGS, S_N, S_PRIM_KEY, S_PRIM_KIND, S_PRIM_ID, S_PRIM_INST, S_LAST_KEY = 0, 1, 2, 3, 4, 5, 6
S_LAST_KIND, S_LAST_ID, S_LAST_INST = 7, 8, 9
S_RULE_KEY, S_RULE_INST = 10, 11  # the first rule source (named by policy rows)
N_SCRATCH_INT = 12
SF_OL, SF_OU, SF_IL, SF_IU, SF_LAST_L, SF_LAST_U, SF_HULL_L, SF_HULL_U = 0, 1, 2, 3, 4, 5, 6, 7
N_SCRATCH_FLOAT = 8

# source keys order sources: facts, then external facts, then rule groundings by rank
KEY_STRIDE = np.int64(1) << np.int64(40)


@njit(cache=True)
def _holds(lo, up, cl, cu, neg):
    if neg:
        a = 1.0 - up
        b = 1.0 - lo
    else:
        a = lo
        b = up
    return a >= cl - EPS and b <= cu + EPS


@njit(cache=True)
def _activate(w, g, act, act_n, act_pos):
    n = act_n[w]
    act[w, n] = g
    act_pos[w, g] = n
    act_n[w] = n + 1


@njit(cache=True)
def _deactivate(w, g, act, act_n, act_pos):
    p = act_pos[w, g]
    last = act[w, act_n[w] - 1]
    act[w, p] = last
    act_pos[w, last] = p
    act_pos[w, g] = -1
    act_n[w] -= 1


@njit(cache=True)
def _watch(w, a, ol, ou, nl, nu, w_ptr, w_inst, w_neg, w_bnd, unsat, act, act_n, act_pos, alog, stats):
    """Update the unsatisfied-clause counts of the groundings that read atom a. Groundings that become
    active are appended to the activation log alog (alog[0] counts; on overflow it is set to -1)."""
    stats[w, STAT_WATCH_VISITS] += w_ptr[a + 1] - w_ptr[a]
    for e in range(w_ptr[a], w_ptr[a + 1]):
        cl = w_bnd[e, 0]
        cu = w_bnd[e, 1]
        neg = w_neg[e]
        was = _holds(ol, ou, cl, cu, neg)
        now = _holds(nl, nu, cl, cu, neg)
        if was == now:
            continue
        g = w_inst[e]
        if was:
            unsat[w, g] += 1
            if unsat[w, g] == 1:
                _deactivate(w, g, act, act_n, act_pos)
        else:
            unsat[w, g] -= 1
            if unsat[w, g] == 0:
                _activate(w, g, act, act_n, act_pos)
                n = alog[0]
                if n >= 0:
                    if n + 1 < alog.shape[0]:
                        alog[n + 1] = g
                        alog[0] = n + 1
                    else:
                        alog[0] = -1


@njit(cache=True)
def _grow_trace(tri, trf, need):
    cap = tri.shape[1]
    if need <= cap:
        return tri, trf
    new_cap = max(need, 2 * cap, 1024)
    ntri = np.empty((TRACE_INT_COLUMNS, new_cap), np.int32)
    ntrf = np.empty((TRACE_FLOAT_COLUMNS, new_cap), np.float64)
    ntri[:, :cap] = tri
    ntrf[:, :cap] = trf
    return ntri, ntrf


@njit(cache=True)
def _log(tri, trf, tr_n, w, t, pass_no, a, ol, ou, nl, nu, kind, cid, inst, nsrc):
    n = tr_n[0]
    tri, trf = _grow_trace(tri, trf, n + 1)
    tri[0, n] = w
    tri[1, n] = t
    tri[2, n] = pass_no
    tri[3, n] = a
    tri[4, n] = kind
    tri[5, n] = cid
    tri[6, n] = inst
    tri[7, n] = nsrc
    trf[0, n] = ol
    trf[1, n] = ou
    trf[2, n] = nl
    trf[3, n] = nu
    tr_n[0] = n + 1
    return tri, trf


@njit(cache=True)
def _add_source(a, l, u, override, key, kind, cid, inst, static_src, si, sf, touched, n_touched):
    """Add one source's bound for atom a to the pending group of this pass."""
    flags = si[a, S_FLAGS]
    if flags & F_TOUCHED == 0:
        touched[n_touched[0]] = a
        n_touched[0] += 1
        flags = F_TOUCHED
        si[a, S_N] = 0
        si[a, S_PRIM_KEY] = key
        si[a, S_PRIM_KIND] = kind
        si[a, S_PRIM_ID] = cid
        si[a, S_PRIM_INST] = inst
        si[a, S_LAST_KEY] = key
        si[a, S_LAST_KIND] = kind
        si[a, S_LAST_ID] = cid
        si[a, S_LAST_INST] = inst
        si[a, S_RULE_KEY] = key if kind == CAUSE_RULE else -1
        si[a, S_RULE_INST] = inst if kind == CAUSE_RULE else -1
        sf[a, SF_LAST_L] = l
        sf[a, SF_LAST_U] = u
        sf[a, SF_HULL_L] = l
        sf[a, SF_HULL_U] = u
    else:
        if kind == CAUSE_RULE and (si[a, S_RULE_KEY] < 0 or key < si[a, S_RULE_KEY]):
            si[a, S_RULE_KEY] = key
            si[a, S_RULE_INST] = inst
        if key < si[a, S_PRIM_KEY]:
            si[a, S_PRIM_KEY] = key
            si[a, S_PRIM_KIND] = kind
            si[a, S_PRIM_ID] = cid
            si[a, S_PRIM_INST] = inst
        if key >= si[a, S_LAST_KEY]:
            si[a, S_LAST_KEY] = key
            si[a, S_LAST_KIND] = kind
            si[a, S_LAST_ID] = cid
            si[a, S_LAST_INST] = inst
            sf[a, SF_LAST_L] = l
            sf[a, SF_LAST_U] = u
        sf[a, SF_HULL_L] = min(sf[a, SF_HULL_L], l)
        sf[a, SF_HULL_U] = max(sf[a, SF_HULL_U], u)
    si[a, S_N] += 1
    if static_src:
        flags |= F_STATIC
    if override:
        if flags & F_OVERRIDE == 0:
            flags |= F_OVERRIDE
            sf[a, SF_OL] = l
            sf[a, SF_OU] = u
        else:
            sf[a, SF_OL] = max(sf[a, SF_OL], l)
            sf[a, SF_OU] = min(sf[a, SF_OU], u)
        if sf[a, SF_OL] > sf[a, SF_OU] + EPS:
            flags |= F_EMPTY_O
    else:
        if flags & F_INTERSECT == 0:
            flags |= F_INTERSECT
            sf[a, SF_IL] = l
            sf[a, SF_IU] = u
        else:
            sf[a, SF_IL] = max(sf[a, SF_IL], l)
            sf[a, SF_IU] = min(sf[a, SF_IU], u)
        if sf[a, SF_IL] > sf[a, SF_IU] + EPS:
            flags |= F_EMPTY_I
    si[a, S_FLAGS] = flags


@njit(cache=True)
def _resolve(cl, cu, a, policy, si, sf, out):
    """The new interval of atom a (current [cl,cu]) after its pending group: docs/language.md,
    'Updating an atom'. Writes (lower, upper, inconsistent, freeze) into out."""
    flags = si[a, S_FLAGS]
    inconsistent = (flags & (F_EMPTY_O | F_EMPTY_I)) != 0
    if flags & F_OVERRIDE:
        bl = sf[a, SF_OL]
        bu = sf[a, SF_OU]
    else:
        bl = cl
        bu = cu
    if flags & F_INTERSECT:
        rl = max(bl, sf[a, SF_IL])
        ru = min(bu, sf[a, SF_IU])
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
                nl, nu = sf[a, SF_OL], sf[a, SF_OU]
            if flags & F_INTERSECT:
                nl, nu = max(nl, sf[a, SF_IL]), min(nu, sf[a, SF_IU])
            if ok and nl <= nu + EPS:
                rl, ru = nl, nu
            else:
                rl, ru = sf[a, SF_LAST_L], sf[a, SF_LAST_U]
        elif policy == POLICY_HULL:
            rl = min(cl, sf[a, SF_HULL_L])
            ru = max(cu, sf[a, SF_HULL_U])
    incoming_disagree = (flags & (F_EMPTY_O | F_EMPTY_I)) != 0
    if (flags & F_OVERRIDE) and (flags & F_INTERSECT):
        if max(sf[a, SF_OL], sf[a, SF_IL]) > min(sf[a, SF_OU], sf[a, SF_IU]) + EPS:
            incoming_disagree = True
    out[0] = rl
    out[1] = ru
    out[2] = 1.0 if inconsistent else 0.0
    out[3] = 1.0 if freeze else 0.0
    out[4] = 1.0 if incoming_disagree else 0.0


@njit(cache=True)
def _apply_touched(w, t, pass_no, touched, n_touched, si, sf, lo, up, static, last_cause, policy,
                   w_ptr, w_inst, w_neg, w_bnd, unsat, act, act_n, act_pos,
                   trace_on, tri, trf, tr_n, stats, err, sort_touched, alog, out):
    """Apply every pending group (one per touched atom); `out` is float scratch of length 5.
    Returns (n_changed, status, tri, trf)."""
    n = n_touched[0]
    order = touched[:n]
    if sort_touched:
        _sort_small(order)
    changed = 0
    status = STATUS_OK
    for k in range(n):
        a = order[k]
        nsrc = si[a, S_N]
        kind = si[a, S_PRIM_KIND]
        if kind == CAUSE_RULE:
            stats[w, STAT_FIRINGS] += nsrc
        if static[w, a]:
            stats[w, STAT_STATIC_IGNORED] += nsrc
            si[a, S_FLAGS] = 0
            continue
        cl = lo[w, a]
        cu = up[w, a]
        _resolve(cl, cu, a, policy, si, sf, out)
        nl = out[0]
        nu = out[1]
        inconsistent = out[2] > 0.5
        if inconsistent and policy == POLICY_ABORT:
            err[0] = w
            err[1] = t
            err[2] = a
            err[3] = last_cause[w, a, 0]
            err[4] = last_cause[w, a, 1]
            err[5] = kind
            err[6] = si[a, S_PRIM_ID]
            err[7] = si[a, S_PRIM_INST]
            err[8] = si[a, S_LAST_KIND]
            err[9] = si[a, S_LAST_ID]
            err[10] = si[a, S_LAST_INST]
            err[11] = 1 if out[4] > 0.5 else 0
            si[a, S_FLAGS] = 0
            status = STATUS_INCONSISTENT
            continue
        cause_kind = CAUSE_POLICY if inconsistent else kind
        cause_id = policy if inconsistent else si[a, S_PRIM_ID]
        grounding = si[a, S_RULE_INST] if inconsistent else si[a, S_PRIM_INST]
        if nl != cl or nu != cu:
            changed += 1
            stats[w, STAT_CHANGES] += 1
            if trace_on[w]:
                tri, trf = _log(tri, trf, tr_n, w, t, pass_no, a, cl, cu, nl, nu,
                                cause_kind, cause_id, grounding, nsrc)
            lo[w, a] = nl
            up[w, a] = nu
            last_cause[w, a, 0] = cause_kind
            last_cause[w, a, 1] = cause_id
            _watch(w, a, cl, cu, nl, nu, w_ptr, w_inst, w_neg, w_bnd, unsat, act, act_n, act_pos, alog, stats)
        elif kind == CAUSE_RULE:
            stats[w, STAT_REDERIVATIONS] += nsrc
        if out[3] > 0.5 or si[a, S_FLAGS] & F_STATIC:
            static[w, a] = True
        si[a, S_FLAGS] = 0
    n_touched[0] = 0
    return changed, status, tri, trf


@njit(cache=True)
def _reset_step(w, t, lo, up, static, last_cause, w_ptr, w_inst, w_neg, w_bnd, unsat, act, act_n,
                act_pos, trace_on, tri, trf, tr_n, stats, alog):
    """`%timesteps reset`: every non-static atom goes back to [0,1] at the start of a step."""
    for a in range(lo.shape[1]):
        if static[w, a]:
            continue
        cl = lo[w, a]
        cu = up[w, a]
        if cl == 0.0 and cu == 1.0:
            continue
        if trace_on[w]:
            tri, trf = _log(tri, trf, tr_n, w, t, 0, a, cl, cu, 0.0, 1.0, CAUSE_RESET, -1, -1, 0)
        stats[w, STAT_CHANGES] += 1
        lo[w, a] = 0.0
        up[w, a] = 1.0
        last_cause[w, a, 0] = CAUSE_RESET
        last_cause[w, a, 1] = -1
        _watch(w, a, cl, cu, 0.0, 1.0, w_ptr, w_inst, w_neg, w_bnd, unsat, act, act_n, act_pos, alog, stats)
    return tri, trf


@njit(cache=True)
def _sort_small(a):
    """Sort in place: insertion sort for the few atoms a pass usually touches, numpy's sort beyond."""
    n = a.shape[0]
    if n > 32:
        a[:] = np.sort(a)
        return
    for i in range(1, n):
        x = a[i]
        j = i - 1
        while j >= 0 and a[j] > x:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = x


@njit(cache=True)
def _heap_push(heap, n, key, g):
    i = n
    heap[i, 0] = key
    heap[i, 1] = g
    while i > 0:
        parent = (i - 1) >> 1
        if heap[parent, 0] <= heap[i, 0]:
            break
        k0, g0 = heap[parent, 0], heap[parent, 1]
        heap[parent, 0], heap[parent, 1] = heap[i, 0], heap[i, 1]
        heap[i, 0], heap[i, 1] = k0, g0
        i = parent
    return n + 1


@njit(cache=True)
def _heap_pop(heap, n):
    g = heap[0, 1]
    n -= 1
    heap[0, 0], heap[0, 1] = heap[n, 0], heap[n, 1]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= n:
            break
        c = left
        if left + 1 < n and heap[left + 1, 0] < heap[left, 0]:
            c = left + 1
        if heap[i, 0] <= heap[c, 0]:
            break
        k0, g0 = heap[c, 0], heap[c, 1]
        heap[c, 0], heap[c, 1] = heap[i, 0], heap[i, 1]
        heap[i, 0], heap[i, 1] = k0, g0
        i = c
    return g, n


@njit(cache=True)
def _would_change(cl, cu, l, u, override, policy):
    """Would one source with bound [l,u] change an atom now [cl,cu]? (docs/language.md, one source)"""
    if override:
        rl, ru = l, u
    else:
        rl, ru = max(cl, l), min(cu, u)
    if rl > ru + EPS:  # inconsistent: the policy decides
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


@njit(cache=True)
def _grow_pending(pend, need):
    cap = pend.shape[1]
    if need <= cap:
        return pend
    npend = np.empty((pend.shape[0], max(need, 2 * cap, 16), 2), np.int32)
    npend[:, :cap] = pend
    return npend


@njit(cache=True)
def step_worlds(cfg, rule_i, rule_f, inst_i, inst_kind, w_ptr, w_inst, w_neg, w_bnd, ih_ptr, ih_inst,
                fact_i, fact_f, fact_order, ext_ptr, ext_i, ext_f, settable,
                lo, up, static, last_cause, unsat, act, act_n, act_pos, pend, pend_n,
                trace_on, tri, trf, tr_n, stats, err, si, sf, touched, heap, in_heap, alog):
    """Compute timestep cfg[CFG_T] for every world. Returns (status, tri, trf, pend): the trace and
    pending arrays are returned because they may have been reallocated to grow."""
    t = cfg[CFG_T]
    prog_mode = cfg[CFG_MODE]
    policy = cfg[CFG_POLICY]
    max_passes = cfg[CFG_MAX_PASSES]
    max_immediate = cfg[CFG_MAX_IMMEDIATE]
    n_worlds = lo.shape[0]
    for e in range(ext_ptr[n_worlds]):  # checked before any world steps, so a refusal changes nothing
        if not settable[ext_i[e, 0]]:
            err[2] = ext_i[e, 0]
            return STATUS_NOT_SETTABLE, tri, trf, pend
    n_touched = np.zeros(1, np.int64)
    out = np.empty(5)
    for w in range(n_worlds):
        # 1. start of the step
        if cfg[CFG_RESET] == 1 and t > 0:
            tri, trf = _reset_step(w, t, lo, up, static, last_cause, w_ptr, w_inst, w_neg, w_bnd,
                                   unsat, act, act_n, act_pos, trace_on, tri, trf, tr_n, stats, alog)
        # 2. pass 0: program facts in their window, external facts, firings scheduled for t
        fact_override = prog_mode == MODE_OVERRIDE
        for k in range(fact_order.shape[0]):
            f = fact_order[k]
            if fact_i[f, 2] < t:
                break
            if fact_i[f, 1] <= t:
                _add_source(fact_i[f, 0], fact_f[f, 0], fact_f[f, 1], fact_override, np.int64(f),
                            CAUSE_FACT, f, -1, fact_i[f, 3] == 1, si, sf, touched, n_touched)
        for e in range(ext_ptr[w], ext_ptr[w + 1]):
            _add_source(ext_i[e, 0], ext_f[e, 0], ext_f[e, 1], fact_override,
                        KEY_STRIDE + ext_i[e, 2], CAUSE_EXTERNAL, ext_i[e, 2], -1, ext_i[e, 1] == 1,
                        si, sf, touched, n_touched)
        kept = 0
        for p in range(pend_n[w]):
            g = pend[w, p, 1]
            if pend[w, p, 0] == t:
                r = inst_i[g, INST_RULE]
                _add_source(inst_i[g, INST_HEAD], rule_f[r, 0], rule_f[r, 1],
                            rule_i[r, RULE_MODE] == MODE_OVERRIDE, 2 * KEY_STRIDE + inst_i[g, INST_RANK],
                            CAUSE_RULE, r, g, False, si, sf, touched, n_touched)
            else:
                pend[w, kept, 0] = pend[w, p, 0]
                pend[w, kept, 1] = g
                kept += 1
        pend_n[w] = kept
        _, status, tri, trf = _apply_touched(w, t, 0, touched, n_touched, si, sf, lo, up, static,
                                             last_cause, policy, w_ptr, w_inst, w_neg, w_bnd, unsat,
                                             act, act_n, act_pos, trace_on, tri, trf, tr_n, stats,
                                             err, True, alog, out)
        if status != STATUS_OK:
            return status, tri, trf, pend
        # 3. fixpoint: immediate phase, then one simultaneous ordinary pass, until nothing changes
        pass_no = 1
        n_immediate = 0
        while True:
            # immediate phase: apply the first (lowest rank) active immediate grounding that would change
            # its head, one at a time. Candidates wait in a min-heap by rank; a grounding enters it when
            # the phase starts, when it becomes active, and when an atom it sets changes.
            hn = 0
            for k in range(act_n[w]):
                g = act[w, k]
                if inst_kind[g] & KIND_IMMEDIATE and not in_heap[g]:
                    hn = _heap_push(heap, hn, inst_i[g, INST_RANK], g)
                    in_heap[g] = True
            while hn > 0:
                g, hn = _heap_pop(heap, hn)
                in_heap[g] = False
                stats[w, STAT_CANDIDATES] += 1
                if unsat[w, g] != 0:
                    continue
                r = inst_i[g, INST_RULE]
                a = inst_i[g, INST_HEAD]
                if static[w, a]:
                    continue
                if not _would_change(lo[w, a], up[w, a], rule_f[r, 0], rule_f[r, 1],
                                     rule_i[r, RULE_MODE] == MODE_OVERRIDE, policy):
                    continue
                n_immediate += 1
                if n_immediate > max_immediate:
                    err[0] = w
                    err[1] = t
                    err[2] = a
                    return STATUS_IMMEDIATE_LIMIT, tri, trf, pend
                _add_source(a, rule_f[r, 0], rule_f[r, 1], rule_i[r, RULE_MODE] == MODE_OVERRIDE,
                            2 * KEY_STRIDE + inst_i[g, INST_RANK], CAUSE_RULE, r, g, False, si, sf,
                            touched, n_touched)
                alog[0] = 0
                _, status, tri, trf = _apply_touched(w, t, pass_no, touched, n_touched, si, sf, lo, up,
                                                     static, last_cause, policy, w_ptr, w_inst, w_neg,
                                                     w_bnd, unsat, act, act_n, act_pos, trace_on, tri,
                                                     trf, tr_n, stats, err, False, alog, out)
                if status != STATUS_OK:
                    return status, tri, trf, pend
                if alog[0] < 0:  # too many activations to log: take every active grounding again
                    for k in range(act_n[w]):
                        g2 = act[w, k]
                        if inst_kind[g2] & KIND_IMMEDIATE and not in_heap[g2]:
                            hn = _heap_push(heap, hn, inst_i[g2, INST_RANK], g2)
                            in_heap[g2] = True
                else:
                    for k in range(1, alog[0] + 1):
                        g2 = alog[k]
                        if inst_kind[g2] & KIND_IMMEDIATE and not in_heap[g2]:
                            hn = _heap_push(heap, hn, inst_i[g2, INST_RANK], g2)
                            in_heap[g2] = True
                # the atom changed: the immediate groundings that set it may now change it back
                for k in range(ih_ptr[a], ih_ptr[a + 1]):
                    g2 = ih_inst[k]
                    if unsat[w, g2] == 0 and not in_heap[g2]:
                        hn = _heap_push(heap, hn, inst_i[g2, INST_RANK], g2)
                        in_heap[g2] = True
            # ordinary pass: every active Δt = 0 grounding fires; heads applied together per atom
            for k in range(act_n[w]):
                g = act[w, k]
                if inst_kind[g] & KIND_ORDINARY == 0:
                    continue
                r = inst_i[g, INST_RULE]
                _add_source(inst_i[g, INST_HEAD], rule_f[r, 0], rule_f[r, 1],
                            rule_i[r, RULE_MODE] == MODE_OVERRIDE, 2 * KEY_STRIDE + inst_i[g, INST_RANK],
                            CAUSE_RULE, r, g, False, si, sf, touched, n_touched)
            changed, status, tri, trf = _apply_touched(w, t, pass_no, touched, n_touched, si, sf, lo,
                                                       up, static, last_cause, policy, w_ptr, w_inst,
                                                       w_neg, w_bnd, unsat, act, act_n, act_pos,
                                                       trace_on, tri, trf, tr_n, stats, err, True, alog, out)
            if status != STATUS_OK:
                return status, tri, trf, pend
            stats[w, STAT_PASSES] += 1
            if changed == 0:
                break
            pass_no += 1
            if pass_no > max_passes:
                err[0] = w
                err[1] = t
                err[2] = -1
                return STATUS_NO_FIXPOINT, tri, trf, pend
        # 4. delayed rules read the final interpretation of t and schedule their heads
        for k in range(act_n[w]):
            g = act[w, k]
            if inst_kind[g] & KIND_DELAYED:
                d = rule_i[inst_i[g, INST_RULE], RULE_DELAY]
                n = pend_n[w]
                pend = _grow_pending(pend, n + 1)
                pend[w, n, 0] = t + d
                pend[w, n, 1] = g
                pend_n[w] = n + 1
    return STATUS_OK, tri, trf, pend


@njit(cache=True)
def _recount(w, g, lo, up, b_ptr, b_atom, b_neg, b_bnd, unsat, act, act_n, act_pos):
    """Count grounding g's unsatisfied binding clauses in world w from scratch; activate it at zero."""
    c = 0
    for e in range(b_ptr[g], b_ptr[g + 1]):
        a = b_atom[e]
        if not _holds(lo[w, a], up[w, a], b_bnd[e, 0], b_bnd[e, 1], b_neg[e]):
            c += 1
    unsat[w, g] = c
    act_pos[w, g] = -1
    if c == 0:
        _activate(w, g, act, act_n, act_pos)


@njit(cache=True)
def recount_groundings(first, lo, up, b_ptr, b_atom, b_neg, b_bnd, unsat, act, act_n, act_pos):
    """Counts for groundings first.. in every world (used when the grounding table grows)."""
    for w in range(lo.shape[0]):
        for g in range(first, b_ptr.shape[0] - 1):
            _recount(w, g, lo, up, b_ptr, b_atom, b_neg, b_bnd, unsat, act, act_n, act_pos)


@njit(cache=True)
def recount_worlds(worlds, lo, up, b_ptr, b_atom, b_neg, b_bnd, unsat, act, act_n, act_pos):
    """Counts and active lists of the given worlds rebuilt from scratch (restore after growth)."""
    for i in range(worlds.shape[0]):
        w = worlds[i]
        act_n[w] = 0
        for g in range(b_ptr.shape[0] - 1):
            _recount(w, g, lo, up, b_ptr, b_atom, b_neg, b_bnd, unsat, act, act_n, act_pos)
