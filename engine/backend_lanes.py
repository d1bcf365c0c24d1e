"""Batch state of the lanes kernel (lanes.py): crisp programs, worlds as bits of machine words.

An atom's state in all worlds is bit planes (T: [1,1], F: [0,0], S: static) of ceil(W/64) words; a
grounding's is a mask of the worlds where it is active and its unsatisfied-clause counts, bit-sliced.
Engine.lower/upper are read off the planes (a crisp bound is one of three values). Besides the planes,
the cause of each atom's last change is kept per world (for the messages of `%inconsistency abort`),
tagged with the world's restore count: a restore only counts up, and a cause older than the world's last
restore is that snapshot's.

The batch is cut into shards of whole words, one per thread (Engine(threads=...)): each shard has its own
planes, lists, schedule and scratch, and they step at once (the kernel releases the GIL). The last causes,
restore counts and statistics are shared arrays, each shard writing its own worlds.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from . import kernel as K
from . import lanes as L
from .backend_api import EngineTables
from .kernel_tables import AggregateTables, KernelTables


def world_mask(local: np.ndarray, n_words: int) -> np.ndarray:
    """Words with the bits of the given (shard-local) worlds set."""
    mask = np.zeros(n_words, np.uint64)
    np.bitwise_or.at(mask, local >> 6, np.uint64(1) << (local & 63).astype(np.uint64))
    return mask


class _Shard:
    """Worlds w0 .. w1-1 of the batch: their planes, grounding masks and counts, lists, schedule, scratch
    and trace rows."""

    def __init__(self, eng: EngineTables, w0: int, w1: int, count_bits: int) -> None:
        self.eng, self.w0, self.w1 = eng, w0, w1
        w = w1 - w0
        nw = self.n_words = (w + 63) // 64
        self.valid = world_mask(np.arange(w), nw)
        self.st = np.zeros((0, L.N_PLANES, nw), np.uint64)
        # per grounding and word: the mask of worlds where it is active, then its unsatisfied-clause
        # counts bit-sliced (enough bits for the rule with the most binding clauses)
        self.gs = np.zeros((0, nw, 1 + count_bits), np.uint64)
        self.alist = np.zeros(0, np.int32)
        self.alist_n = np.zeros(K.N_KINDS, np.int64)
        self.apos = np.zeros(0, np.int32)
        self.pend_due = np.zeros(16, np.int64)
        self.pend_g = np.zeros(16, np.int32)
        self.pend_m = np.zeros((16, nw), np.uint64)
        self.pend_n = np.zeros(1, np.int64)
        self.ctl = np.zeros(L.N_CTL, np.int64)
        self.n_touched = np.zeros(1, np.int64)
        self.src_n = np.zeros(1, np.int64)
        self.hn = np.zeros(1, np.int64)
        self.n_imm = np.zeros(w, np.int64)
        self.pw = np.zeros((L.N_PW, w), np.int64)
        self.ws = np.zeros((L.N_WSCRATCH, nw), np.uint64)
        self.wl = np.zeros(nw, np.int64)
        self.wmask = np.zeros(nw, np.uint64)  # restore's scratch
        self.src_i = np.zeros((0, 6), np.int64)
        self.src_m = np.zeros((0, nw), np.uint64)
        self.err = np.zeros(K.N_ERR, np.int64)
        # trace rows of this shard's step, appended to the engine's buffer afterwards
        self.tri = np.zeros((1024, K.TRACE_INT_COLUMNS), np.int32)
        self.trf = np.zeros((1024, K.TRACE_FLOAT_COLUMNS), np.float64)
        self.tr_n = np.zeros(1, np.int64)
        self.scratch(0, 0)

    def scratch(self, n_atoms: int, n_inst: int) -> None:
        nw = self.n_words
        self.slot_of = np.full(max(n_atoms, 1), -1, np.int32)
        self.touched = np.zeros(max(n_atoms, 1), np.int32)
        self.gm = np.zeros((max(n_atoms, 1), L.N_GPLANES, nw), np.uint64)
        self.slot_src = np.full(max(n_atoms, 1), -1, np.int64)
        self.heap = np.zeros(max(n_inst, 1), np.int64)
        self.in_heap = np.zeros(max(n_inst, 1), np.bool_)

    def grow(self, n_atoms: int, kt: KernelTables, kind_base: np.ndarray) -> None:
        nw = self.n_words
        if n_atoms > len(self.st):
            self.st = np.concatenate([self.st, np.zeros((n_atoms - len(self.st), L.N_PLANES, nw), np.uint64)])
        n_inst, first = len(kt.inst), len(self.gs)
        if n_inst > first:
            self.gs = np.concatenate([self.gs, np.zeros((n_inst - first, nw, self.gs.shape[2]), np.uint64)])
            self.alist = np.zeros(n_inst, np.int32)
            self.apos = np.full(n_inst, -1, np.int32)
            L.fill_counts(first, self.valid, self.st, kt.b_ptr, kt.b_atom, kt.b_code, self.gs,
                          kt.inst, self.alist, self.alist_n, self.apos, kind_base)
            self.ctl[L.C_SETTLED] = 0  # new groundings, none of them a candidate yet
        self.scratch(n_atoms, n_inst)

    def step(self, batch: LaneState, ext_ptr: np.ndarray, ext_i: np.ndarray, ext_v: np.ndarray) -> int:
        eng, kt, w0, w1 = self.eng, batch.kt, self.w0, self.w1
        ext_ptr = ext_ptr[w0:w1 + 1]
        tmask = np.packbits(np.append(eng.trace_on[w0:w1], np.zeros(self.n_words * 64 - (w1 - w0), np.bool_)),
                            bitorder="little").view(np.uint64)
        # sources of one pass: facts, external rows and due firings (pass 0), or ordinary groundings
        need = len(eng._fact_i) + int(ext_ptr[-1] - ext_ptr[0]) + int(self.pend_n[0]) + batch.n_ordinary
        if need > len(self.src_i):
            self.src_i = np.zeros((max(need, 2 * len(self.src_i)), 6), np.int64)
            self.src_m = np.zeros((len(self.src_i), self.n_words), np.uint64)
        self.tr_n[0] = 0
        self.ctl[L.C_PHASE] = L.PH_START
        stats = eng._stats[w0:w1]
        while True:
            status = L.step_lanes(
                eng._cfg, w0, self.ctl, eng._rule_i, eng._rule_v, kt.inst, batch.kind_base, kt.wc_ptr,
                kt.wc_code, kt.wc_gptr, kt.wg, kt.ih_ptr, kt.ih_inst, eng._fact_i, eng._fact_v,
                eng._fact_order, ext_ptr, ext_i, ext_v, eng._settable, self.valid, tmask, self.st, batch.wep,
                batch.lc, self.gs, self.alist, self.alist_n, self.apos, self.pend_due, self.pend_g,
                self.pend_m, self.pend_n, self.tri, self.trf, self.tr_n, stats, self.err, self.slot_of,
                self.touched, self.n_touched, self.gm, self.slot_src, self.src_i, self.src_m, self.src_n,
                self.heap, self.hn, self.in_heap, self.n_imm, self.pw, self.ws, self.wl)
            if status == K.STATUS_TRACE_ROOM:  # a unit of work may write a row per world
                self.grow_trace(int(self.tr_n[0]) + max(int(eng._cfg[K.CFG_TRACE_ROOM]), w1 - w0))
            elif status == K.STATUS_PEND_ROOM:
                self.grow_pending(int(self.pend_n[0]) + int(self.alist_n[K.KIND_DELAYED]))
            else:
                break
        if status != K.STATUS_OK:  # an error may leave candidates and scratch rows behind
            self.in_heap[:] = False
            self.slot_of[:] = -1
            self.n_touched[0] = 0
            self.src_n[0] = 0
            self.hn[0] = 0
        return status

    def grow_trace(self, need: int) -> None:
        n = int(self.tr_n[0])
        cap = max(need, 2 * len(self.tri))
        tri, trf = np.empty((cap, K.TRACE_INT_COLUMNS), np.int32), np.empty((cap, K.TRACE_FLOAT_COLUMNS))
        tri[:n], trf[:n] = self.tri[:n], self.trf[:n]
        self.tri, self.trf = tri, trf

    def grow_pending(self, need: int) -> None:
        cap = max(need, 2 * len(self.pend_g), 16)
        n = int(self.pend_n[0])
        due, g, m = np.zeros(cap, np.int64), np.zeros(cap, np.int32), np.zeros((cap, self.n_words), np.uint64)
        due[:n], g[:n], m[:n] = self.pend_due[:n], self.pend_g[:n], self.pend_m[:n]
        self.pend_due, self.pend_g, self.pend_m = due, g, m

    def snapshot(self) -> dict[str, Any]:
        n = int(self.pend_n[0])
        return {"st": self.st.copy(), "gs": self.gs.copy(), "settled": int(self.ctl[L.C_SETTLED]),
                "pend_due": self.pend_due[:n].copy(), "pend_g": self.pend_g[:n].copy(),
                "pend_m": self.pend_m[:n].copy()}

    def restore(self, batch: LaneState, part: dict[str, Any], local: np.ndarray, shift: int) -> None:
        kt = batch.kt
        need = int(self.pend_n[0]) + len(part["pend_g"])
        if need > len(self.pend_g):
            self.grow_pending(need)
        self._settle_after_restore(part)
        L.restore_worlds(local, shift, part["st"], part["gs"], part["pend_due"], part["pend_g"], part["pend_m"],
                         self.st, self.gs, kt.inst, self.alist, self.alist_n, self.apos, batch.kind_base,
                         self.pend_due, self.pend_g, self.pend_m, self.pend_n, self.wmask)
        self._recount_if_grown(batch, part)

    def restore_from(self, batch: LaneState, part: dict[str, Any], local: np.ndarray, sources: np.ndarray,
                     shift: int) -> None:
        """Worlds `local` take the states of `part`'s worlds `sources` (local to that snapshot part)."""
        need = int(self.pend_n[0]) + len(part["pend_g"]) * len(local)
        if need > len(self.pend_g):
            self.grow_pending(need)
        self._settle_after_restore(part)
        L.restore_worlds_from(local, sources, shift, part["st"], part["gs"], part["pend_due"], part["pend_g"],
                              part["pend_m"], self.st, self.gs, batch.kt.inst, self.alist, self.alist_n,
                              self.apos, batch.kind_base, self.pend_due, self.pend_g, self.pend_m, self.pend_n)
        self._recount_if_grown(batch, part)

    def _settle_after_restore(self, part: dict[str, Any]) -> None:
        """The restored worlds are settled (lanes.C_SETTLED) if the snapshot was and no grounding came after it."""
        if not part["settled"] or len(part["gs"]) < len(self.gs):
            self.ctl[L.C_SETTLED] = 0

    def _recount_if_grown(self, batch: LaneState, part: dict[str, Any]) -> None:
        if len(part["gs"]) < len(self.gs):  # groundings grew: count them all again
            kt = batch.kt
            L.fill_counts(0, self.valid, self.st, kt.b_ptr, kt.b_atom, kt.b_code, self.gs, kt.inst,
                          self.alist, self.alist_n, self.apos, batch.kind_base)

    def pending(self, local: int) -> list[tuple[int, int]]:
        n = int(self.pend_n[0])
        bit = np.uint64(1) << np.uint64(local & 63)
        sel = np.flatnonzero(self.pend_m[:n, local >> 6] & bit)
        return [(int(self.pend_due[i]), int(self.pend_g[i])) for i in sel]


class LaneState:
    name = "lanes"
    events = 0  # ids of snapshots, unique in the process

    def __init__(self, eng: EngineTables, threads: int = 1) -> None:
        self.eng = eng
        w = eng.n_worlds
        # last cause per [atom, world]: kind, id, and the world's restore count when it was written
        self.lc = np.zeros((0, w, 3), np.int32)
        self.wep = np.zeros(w, np.int32)  # restores per world
        self.lc_snap = np.full(w, -1, np.int64)  # the snapshot each world was last restored from
        self.lc_col = np.arange(w)  # the world of that snapshot whose state it took
        self._snap_lc: dict[int, np.ndarray] = {}  # those snapshots' last causes [atom, world, 2]
        self.kind_base = np.zeros(K.N_KINDS, np.int64)
        self.n_ordinary = 0
        most = max((sum(c.binds for c in r.body) for r in eng.rules), default=0)
        words = (w + 63) // 64
        n_shards = max(1, min(threads, words))
        cuts = [64 * (words * i // n_shards) for i in range(n_shards)] + [w]
        self.shards = [_Shard(eng, cuts[i], cuts[i + 1], max(int(most).bit_length(), 1)) for i in range(n_shards)]
        self._pool = ThreadPoolExecutor(n_shards) if n_shards > 1 else None

    # ---- the Engine's view ----

    @property
    def n_atoms(self) -> int:
        return self.lc.shape[0]

    @property
    def lower(self) -> np.ndarray:
        """[world, atom]: 1.0 where [1,1], else 0.0 (a copy, read off plane T)."""
        return self.truth_plane(np.arange(self.n_atoms), L.P_T).astype(np.float64)

    @property
    def upper(self) -> np.ndarray:
        """[world, atom]: 0.0 where [0,0], else 1.0 (a copy, read off plane F)."""
        return 1.0 - self.truth_plane(np.arange(self.n_atoms), L.P_F)

    @property
    def static(self) -> np.ndarray:
        return self.truth_plane(np.arange(self.n_atoms), L.P_S)

    @property
    def last_cause(self) -> np.ndarray:
        """[world, atom, 2]: kind and id of each atom's last change (a copy)."""
        return self._resolved_causes().transpose(1, 0, 2)

    def _shard_of(self, world: int) -> _Shard:
        return next(s for s in self.shards if s.w0 <= world < s.w1)

    def bound(self, atom: int, world: int) -> tuple[float, float]:
        sh = self._shard_of(world)
        local = world - sh.w0
        bit = np.uint64(1) << np.uint64(local & 63)
        t = bool(sh.st[atom, L.P_T, local >> 6] & bit)
        f = bool(sh.st[atom, L.P_F, local >> 6] & bit)
        return (1.0 if t else 0.0), (0.0 if f else 1.0)

    def truth(self, atoms: np.ndarray, value: float) -> np.ndarray:
        """bool [worlds, atoms]: value 1.0, where each atom is [1,1]; value 0.0, where it is [0,0]."""
        return self.truth_plane(atoms, L.P_T if value == 1.0 else L.P_F)

    def truth_plane(self, atoms: np.ndarray, plane: int) -> np.ndarray:
        out = np.zeros((self.eng.n_worlds, len(atoms)), np.bool_)
        for sh in self.shards:
            L.plane_truth(sh.st, plane, atoms, sh.w0, sh.w1 - sh.w0, out)
        return out

    def _resolved_causes(self) -> np.ndarray:
        """[atom, world, 2]: the last causes, those older than a world's last restore taken from the
        snapshot it was restored from."""
        out = self.lc[:, :, :2].copy()
        stale = self.lc[:, :, 2] != self.wep[None, :]
        for sid, src in self._snap_lc.items():
            worlds = np.flatnonzero(self.lc_snap == sid)
            theirs = np.full((len(out), len(worlds), 2), -1, np.int32)
            n = min(len(src), len(out))
            theirs[:n] = src[:n][:, self.lc_col[worlds]]
            out[:, worlds] = np.where(stale[:, worlds, None], theirs, out[:, worlds])
        return out

    def _snapshot_cause(self, atom: int, world: int) -> tuple[int, int]:
        src = self._snap_lc.get(int(self.lc_snap[world]))
        if src is None or atom >= len(src):
            return -1, -1
        col = int(self.lc_col[world])
        return int(src[atom, col, 0]), int(src[atom, col, 1])

    # ---- building ----

    def grow(self, n_atoms: int, kt: KernelTables, agg: AggregateTables) -> None:
        """Room for n_atoms atoms and every grounding of kt (agg is not read: the engine runs the counting
        kernel for aggregated rules)."""
        w = self.eng.n_worlds
        grow = n_atoms - self.n_atoms
        if grow > 0:
            new = np.full((grow, w, 3), -1, np.int32)
            new[:, :, 2] = self.wep  # never set, in this episode as in any snapshot
            self.lc = np.concatenate([self.lc, new])
        self.kt = kt
        counts = np.bincount(kt.inst[:, K.INST_KIND], minlength=K.N_KINDS)
        self.kind_base = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        self.n_ordinary = int(counts[K.KIND_ORDINARY])
        for sh in self.shards:
            sh.grow(n_atoms, kt, self.kind_base)

    # ---- stepping ----

    def step(self, ext_ptr: np.ndarray, ext_i: np.ndarray, ext_f: np.ndarray) -> int:
        eng = self.eng
        ext_v = eng._ext_codes  # the Engine found them crisp
        if self._pool is None:
            statuses = [self.shards[0].step(self, ext_ptr, ext_i, ext_v)]
        else:
            futures = [self._pool.submit(sh.step, self, ext_ptr, ext_i, ext_v) for sh in self.shards]
            statuses = [f.result() for f in futures]
        for sh, status in zip(self.shards, statuses):
            if status != K.STATUS_OK:  # the first world's error, as one world after another would find it
                eng._err[:] = sh.err
                if status == K.STATUS_INCONSISTENT and eng._err[K.E_OLD_KIND] == L.CAUSE_SNAPSHOT:
                    eng._err[K.E_OLD_KIND], eng._err[K.E_OLD_ID] = self._snapshot_cause(
                        int(eng._err[K.E_ATOM]), int(eng._err[K.E_WORLD]))
                return status
        for sh in self.shards:
            n = int(sh.tr_n[0])
            if n:
                # rows came world after world within each unit of work: order them by world (stable), as
                # the counting kernel writes them
                # (16-bit keys sort by radix, and take() with mode="clip" writes in place: a 20v20 x256
                # step's 140k rows took ~25 ms by int32 argsort and fancy indexing, ~8 ms so)
                world = sh.tri[:n, 0]
                order = np.argsort(world.astype(np.uint16) if eng.n_worlds <= 1 << 16 else world, kind="stable")
                start = int(eng._tr_n[0])
                if start + n > len(eng._tri):
                    eng._grow_trace(start + n)
                np.take(sh.tri[:n], order, axis=0, out=eng._tri[start:start + n], mode="clip")
                np.take(sh.trf[:n], order, axis=0, out=eng._trf[start:start + n], mode="clip")
                eng._tr_n[0] = start + n
        return K.STATUS_OK

    # ---- snapshots ----

    def snapshot(self) -> dict[str, Any]:
        LaneState.events += 1
        return {"id": LaneState.events, "lc": self._resolved_causes(),
                "shards": [sh.snapshot() for sh in self.shards]}

    def restore(self, snap: dict[str, Any], indices: np.ndarray, shift: int, sources: np.ndarray | None = None
                ) -> None:
        """Worlds `indices` take their state from snap's worlds `sources` (default: the same worlds)."""
        if sources is None:
            for sh, part in zip(self.shards, snap["shards"]):
                local = indices[(indices >= sh.w0) & (indices < sh.w1)] - sh.w0
                if len(local):
                    sh.restore(self, part, local, shift)
        else:
            for sh in self.shards:
                mine = (indices >= sh.w0) & (indices < sh.w1)
                for j, (src, part) in enumerate(zip(self.shards, snap["shards"])):
                    pick = mine & (sources >= src.w0) & (sources < src.w1)
                    if pick.any():
                        sh.restore_from(self, part, indices[pick] - sh.w0, sources[pick] - src.w0, shift)
        # their last causes are now the snapshot's (its column `sources`): count their restores on, so
        # every cause is older
        self.lc_col[indices] = indices if sources is None else sources
        self.wep[indices] += 1
        if snap["id"] not in self._snap_lc:  # forget the snapshots no world refers to any more
            live = set(np.unique(self.lc_snap).tolist())
            self._snap_lc = {sid: lc for sid, lc in self._snap_lc.items() if sid in live}
            self._snap_lc[snap["id"]] = snap["lc"]
        self.lc_snap[indices] = snap["id"]

    def pending(self, world: int) -> list[tuple[int, int]]:
        sh = self._shard_of(world)
        return sh.pending(world - sh.w0)

    def export(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[list[tuple[int, int]]]]:
        """The batch as the counting backend holds it: lower, upper, static, last_cause [world, atom],
        and each world's schedule."""
        return (self.lower, self.upper, self.static, self.last_cause,
                [self.pending(w) for w in range(self.eng.n_worlds)])
