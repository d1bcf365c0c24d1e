"""The counting kernel's restore of one or a few worlds, compiled: the groundings' counts copied, and the
active lists rebuilt from the snapshot's instead of copying every grounding's list entry and position.

A grounding's position (act_pos) is -1 exactly when it is inactive, and only the first act_n entries of a
kind's list are ever read; so a world needs: the positions of its groundings active now cleared, the
snapshot's active prefix and its positions written back, and the counts. At 20 agents a team that is
~2,700 active groundings against 620,052 entries in each of act and act_pos (docs/benchmarks.md)."""
from __future__ import annotations

from numba import njit


@njit(cache=True, _nrt=False)
def restore_groundings(worlds, sources, s_unsat, s_act, s_act_n, unsat, act, act_n, act_pos, kind_base):
    """Worlds `worlds` (int64 indices) take unsat, the active lists and act_n from the snapshot arrays'
    worlds `sources` (int64, one per world; often the same indices); afterwards act_pos and the lists'
    first act_n entries equal the snapshot world's."""
    for i in range(worlds.shape[0]):
        w = worlds[i]
        s = sources[i]
        for k in range(act_n.shape[1]):
            base = kind_base[k]
            for p in range(act_n[w, k]):  # active now: inactive unless the snapshot lists it
                act_pos[w, act[w, base + p]] = -1
        for k in range(act_n.shape[1]):
            base = kind_base[k]
            n = s_act_n[s, k]
            for p in range(n):
                g = s_act[s, base + p]
                act[w, base + p] = g
                act_pos[w, g] = p
            act_n[w, k] = n
        for g in range(unsat.shape[1]):
            unsat[w, g] = s_unsat[s, g]
