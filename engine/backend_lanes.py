"""Batch state of the lanes kernel (lanes.py): crisp programs, worlds as bits of machine words.

An atom's state in all worlds is three bit planes (T: [1,1], F: [0,0], S: static) of ceil(W/64) words; a
grounding's is one mask of the worlds where its body holds. Besides the planes, the float bounds that
Engine.lower/upper show are kept per [atom, world] (written only where an atom changes), and the cause of
each atom's last change per world (for the messages of `%inconsistency abort`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from . import kernel as K
from . import lanes as L

if TYPE_CHECKING:
    from .core import Engine


def crisp_codes(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The lanes value code of each bound ([0,1] V_U, [1,1] V_T, [0,0] V_F), -1 where it is not crisp."""
    lower, upper = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    code = np.full(lower.shape, -1, np.int8)
    code[(lower == 0.0) & (upper == 1.0)] = L.V_U
    code[(lower == 1.0) & (upper == 1.0)] = L.V_T
    code[(lower == 0.0) & (upper == 0.0)] = L.V_F
    return code


class LaneState:
    name = "lanes"
    _events = 0  # ids of snapshots and restores, unique in the process

    def __init__(self, eng: Engine) -> None:
        self.eng = eng
        w = eng.n_worlds
        self.n_words = (w + 63) // 64
        self.valid = np.zeros(self.n_words, np.uint64)
        for i in range(w):
            self.valid[i >> 6] |= np.uint64(1) << np.uint64(i & 63)
        self.st = np.zeros((0, L.N_PLANES, self.n_words), np.uint64)
        self.lo = np.zeros((0, w))
        self.up = np.ones((0, w))
        self.lc = np.full((0, w, 2), -1, np.int32)
        self.active = np.zeros((0, self.n_words), np.uint64)
        self._alist = np.zeros(0, np.int32)
        self._alist_n = np.zeros(K.N_KINDS, np.int64)
        self._apos = np.zeros(0, np.int32)
        self._kind_base = np.zeros(K.N_KINDS, np.int64)
        self._pend_due = np.zeros(16, np.int64)
        self._pend_g = np.zeros(16, np.int32)
        self._pend_m = np.zeros((16, self.n_words), np.uint64)
        self._pend_n = np.zeros(1, np.int64)
        self._ctl = np.zeros(L.N_CTL, np.int64)
        # per world: the id of its last restore, and of the snapshot that restore came from
        self._epoch = np.full(w, -1, np.int64)
        self._source = np.full(w, -1, np.int64)
        self._n_touched = np.zeros(1, np.int64)
        self._src_n = np.zeros(1, np.int64)
        self._hn = np.zeros(1, np.int64)
        self._n_imm = np.zeros(w, np.int64)
        self._pw = np.zeros((L.N_PW, w), np.int64)
        self._ws = np.zeros((L.N_WSCRATCH, self.n_words), np.uint64)
        self._wl = np.zeros(self.n_words, np.int64)
        self._src_i = np.zeros((0, 6), np.int64)
        self._src_m = np.zeros((0, self.n_words), np.uint64)
        self._scratch(0, 0)

    # ---- the Engine's view ----

    @property
    def n_atoms(self) -> int:
        return self.st.shape[0]

    @property
    def lower(self) -> np.ndarray:
        return self.lo.T  # [world, atom], a view

    @property
    def upper(self) -> np.ndarray:
        return self.up.T

    @property
    def static(self) -> np.ndarray:
        bits = np.unpackbits(self.st[:, L.P_S, :].view(np.uint8), axis=1, bitorder="little")
        return bits[:, :self.eng.n_worlds].T.astype(np.bool_)

    @property
    def last_cause(self) -> np.ndarray:
        return self.lc.transpose(1, 0, 2)

    # ---- building ----

    def _scratch(self, n_atoms: int, n_inst: int) -> None:
        nw = self.n_words
        self._slot_of = np.full(max(n_atoms, 1), -1, np.int32)
        self._touched = np.zeros(max(n_atoms, 1), np.int32)
        self._gm = np.zeros((max(n_atoms, 1), L.N_GPLANES, nw), np.uint64)
        self._slot_src = np.full(max(n_atoms, 1), -1, np.int64)
        self._heap = np.zeros(max(n_inst, 1), np.int64)
        self._in_heap = np.zeros(max(n_inst, 1), np.bool_)

    def grow(self, n_atoms: int, kt: dict[str, np.ndarray]) -> None:
        w, nw = self.eng.n_worlds, self.n_words
        grow = n_atoms - self.n_atoms
        if grow > 0:
            self.st = np.concatenate([self.st, np.zeros((grow, L.N_PLANES, nw), np.uint64)])
            self.lo = np.concatenate([self.lo, np.zeros((grow, w))])
            self.up = np.concatenate([self.up, np.ones((grow, w))])
            self.lc = np.concatenate([self.lc, np.full((grow, w, 2), -1, np.int32)])
        self.kt = kt
        n_inst = len(kt["inst"])
        first = self.active.shape[0]
        if n_inst > first:
            self.active = np.concatenate([self.active, np.zeros((n_inst - first, nw), np.uint64)])
            counts = np.bincount(kt["inst"][:, K.INST_KIND], minlength=K.N_KINDS)
            self._kind_base = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
            self._alist = np.zeros(n_inst, np.int32)
            self._apos = np.full(n_inst, -1, np.int32)
            L.fill_active(first, self.valid, self.st, kt["b_ptr"], kt["b_atom"], kt["b_code"], self.active,
                          kt["inst"], self._alist, self._alist_n, self._apos, self._kind_base)
        self._n_ordinary = int(np.count_nonzero(kt["inst"][:, K.INST_KIND] == K.KIND_ORDINARY)) if n_inst else 0
        self._scratch(n_atoms, n_inst)

    # ---- stepping ----

    def step(self, ext_ptr: np.ndarray, ext_i: np.ndarray, ext_f: np.ndarray) -> int:
        eng, kt = self.eng, self.kt
        ext_v = crisp_codes(ext_f[:, 0], ext_f[:, 1])  # the Engine checked that they are crisp
        tmask = np.packbits(np.append(eng.trace_on, np.zeros(self.n_words * 64 - eng.n_worlds, np.bool_)),
                            bitorder="little").view(np.uint64)
        # sources of one pass: facts, external rows and due firings (pass 0), or ordinary groundings
        need = len(eng._fact_i) + len(ext_i) + int(self._pend_n[0]) + self._n_ordinary
        if need > len(self._src_i):
            self._src_i = np.zeros((max(need, 2 * len(self._src_i)), 6), np.int64)
            self._src_m = np.zeros((len(self._src_i), self.n_words), np.uint64)
        first_row = int(eng._tr_n[0])
        self._ctl[L.C_PHASE] = L.PH_START
        while True:
            status = L.step_lanes(
                eng._cfg, self._ctl, eng._rule_i, eng._rule_v, kt["inst"], self._kind_base, kt["wc_ptr"],
                kt["wc_code"], kt["wc_gptr"], kt["wg"], kt["b_ptr"], kt["b_atom"], kt["b_code"], kt["ih_ptr"],
                kt["ih_inst"], eng._fact_i, eng._fact_v, eng._fact_order, ext_ptr, ext_i, ext_v, eng._settable,
                self.valid, tmask, self.st, self.lo, self.up, self.lc, self.active, self._alist, self._alist_n,
                self._apos, self._pend_due, self._pend_g, self._pend_m, self._pend_n, eng._tri, eng._trf,
                eng._tr_n, eng._stats, eng._err, self._slot_of, self._touched, self._n_touched, self._gm,
                self._slot_src, self._src_i, self._src_m, self._src_n, self._heap, self._hn, self._in_heap,
                self._n_imm, self._pw, self._ws, self._wl)
            if status == K.STATUS_TRACE_ROOM:  # a unit of work may write a row per world
                eng._grow_trace(int(eng._tr_n[0]) + max(int(eng._cfg[K.CFG_TRACE_ROOM]), eng.n_worlds))
            elif status == K.STATUS_PEND_ROOM:
                self._grow_pending(int(self._pend_n[0]) + int(self._alist_n[K.KIND_DELAYED]))
            else:
                break
        if status != K.STATUS_OK:  # an error may leave candidates and scratch rows behind
            self._in_heap[:] = False
            self._slot_of[:] = -1
            self._n_touched[0] = 0
            self._src_n[0] = 0
            self._hn[0] = 0
        elif eng.n_worlds > 1 and int(eng._tr_n[0]) > first_row:
            # rows came world after world within each unit of work: order them by world (stable), as the
            # counting kernel writes them
            rows = slice(first_row, int(eng._tr_n[0]))
            order = np.argsort(eng._tri[rows, 0], kind="stable")
            eng._tri[rows] = eng._tri[rows][order]
            eng._trf[rows] = eng._trf[rows][order]
        return status

    def _grow_pending(self, need: int) -> None:
        cap = max(need, 2 * len(self._pend_g), 16)
        n = int(self._pend_n[0])
        due, g, m = np.zeros(cap, np.int64), np.zeros(cap, np.int32), np.zeros((cap, self.n_words), np.uint64)
        due[:n], g[:n], m[:n] = self._pend_due[:n], self._pend_g[:n], self._pend_m[:n]
        self._pend_due, self._pend_g, self._pend_m = due, g, m

    # ---- snapshots ----

    def snapshot(self) -> dict[str, Any]:
        n = int(self._pend_n[0])
        LaneState._events += 1
        return {"id": LaneState._events, "epoch": self._epoch.copy(), "st": self.st.copy(), "active": self.active.copy(), "lo": self.lo.copy(), "up": self.up.copy(),
                "lc": self.lc.copy(), "pend_due": self._pend_due[:n].copy(), "pend_g": self._pend_g[:n].copy(),
                "pend_m": self._pend_m[:n].copy()}

    def restore(self, snap: dict[str, Any], indices: np.ndarray, shift: int) -> None:
        wmask = np.zeros(self.n_words, np.uint64)
        for i in indices:
            wmask[i >> 6] |= np.uint64(1) << np.uint64(i & 63)
        n_atoms = snap["st"].shape[0]
        # a world's unchanged atoms (plane D) still hold the snapshot's bounds if it was last restored
        # from this snapshot, or has not been restored since the snapshot was taken; other worlds copy
        # every atom
        shortcut = (self._source[indices] == snap["id"]) | (self._epoch[indices] == snap["epoch"][indices])
        full_worlds = indices[~shortcut]
        full = np.zeros(self.n_words, np.uint64)
        for i in full_worlds:
            full[i >> 6] |= np.uint64(1) << np.uint64(i & 63)
        L.restore_columns(wmask, full, snap["lo"], snap["up"], snap["lc"], self.st, self.lo, self.up, self.lc)
        LaneState._events += 1
        self._epoch[indices] = LaneState._events
        self._source[indices] = snap["id"]
        self.st[n_atoms:, :L.P_D] &= ~wmask  # atoms interned since the snapshot start unset
        kt = self.kt
        L.restore_lanes(wmask, snap["st"], snap["active"], self.st, self.active, kt["inst"], self._alist,
                        self._alist_n, self._apos, self._kind_base)
        if snap["active"].shape[0] < self.active.shape[0]:  # groundings grew: evaluate them all again
            L.fill_active(0, self.valid, self.st, kt["b_ptr"], kt["b_atom"], kt["b_code"], self.active,
                          kt["inst"], self._alist, self._alist_n, self._apos, self._kind_base)
        # the schedule: these worlds drop theirs and take the snapshot's, `shift` steps later
        n = int(self._pend_n[0])
        m = self._pend_m[:n] & ~wmask
        keep = np.flatnonzero(m.any(axis=1))
        theirs = snap["pend_m"] & wmask
        add = np.flatnonzero(theirs.any(axis=1))
        total = len(keep) + len(add)
        if total > len(self._pend_g):
            self._grow_pending(total)
        due = np.concatenate([self._pend_due[keep], snap["pend_due"][add] + shift])
        g = np.concatenate([self._pend_g[keep], snap["pend_g"][add]])
        mm = np.concatenate([m[keep], theirs[add]])
        self._pend_due[:total], self._pend_g[:total], self._pend_m[:total] = due, g, mm
        self._pend_n[0] = total

    def pending(self, world: int) -> list[tuple[int, int]]:
        n = int(self._pend_n[0])
        bit = np.uint64(1) << np.uint64(world & 63)
        sel = np.flatnonzero(self._pend_m[:n, world >> 6] & bit)
        return [(int(self._pend_due[i]), int(self._pend_g[i])) for i in sel]

    def export(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[list[tuple[int, int]]]]:
        """The batch as the counting backend holds it: lower, upper, static, last_cause [world, atom],
        and each world's schedule."""
        return (self.lower.copy(), self.upper.copy(), self.static, self.last_cause.copy(),
                [self.pending(w) for w in range(self.eng.n_worlds)])
