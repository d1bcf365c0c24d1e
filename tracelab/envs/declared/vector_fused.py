"""A batch of declared worlds' step as ONE compiled call: each world's step facts to engine rows (grouped
by world, as the kernel reads them), the counting kernel's step of every world, and each world's reads.

The batched twin of fused.py, over the same structref (fused.bind; numba compiles it again for these
shapes). Tables are fused.py's with a world axis where a world has its own: `rows` [W, agents] (each
agent's action row, -1: none), `picks` [W, draws] (-1: not drawn), `prev` [W, cap] / `prev_n` [W] (the
step facts each world's last step set), and the reads' results `index` [W, parts], `rewards` [W, agents],
`res` [W, 2] (terminated, truncated), `mask` [W, mask atoms]. `now`/`now_bnd` are one world's scratch."""
from __future__ import annotations

import inspect

from numba import njit

from tracelab.engine import kernel as K
from tracelab.envs.declared import fused
from tracelab.game.rulesim_fused import _stamp_with_sources

STATUS_OK = K.STATUS_OK


@njit(cache=True)
def step_batch(b, rows, picks, t, first_id):  # noqa: ANN001, ANN201
    """fused.fused_step for every world: world w's action rows rows[w] and draws picks[w]; the last
    step's facts not set again become [0,0]. Steps the kernel once for all worlds; on STATUS_OK also
    reads every world (read_batch). Returns the kernel's status (b.out[4][0]: the world it paused at)."""
    act_ptr, act_atoms, act_bnd, draw_base, val_ptr, val_atoms, val_bnd, prev, prev_n, now, now_bnd = b.tables
    ext_ptr, ext_i, ext_f = b.ext
    k = 0
    for w in range(rows.shape[0]):
        ext_ptr[w] = k
        n = 0
        for action in rows[w]:
            if action < 0:
                continue
            for j in range(act_ptr[action], act_ptr[action + 1]):
                now[n] = act_atoms[j]
                now_bnd[n, 0] = act_bnd[j, 0]
                now_bnd[n, 1] = act_bnd[j, 1]
                n += 1
        for d in range(picks.shape[1]):
            if picks[w, d] >= 0:
                v = draw_base[d] + picks[w, d]
                for j in range(val_ptr[v], val_ptr[v + 1]):
                    now[n] = val_atoms[j]
                    now_bnd[n, 0] = val_bnd[j, 0]
                    now_bnd[n, 1] = val_bnd[j, 1]
                    n += 1
        for i in range(prev_n[w]):  # this world's last step facts that are not set again: false now
            again = False
            for j in range(n):
                if now[j] == prev[w, i]:
                    again = True
                    break
            if not again:
                ext_i[k, 0] = prev[w, i]
                ext_i[k, 1] = 0
                ext_i[k, 2] = first_id + k
                ext_f[k, 0] = 0.0
                ext_f[k, 1] = 0.0
                k += 1
        for j in range(n):
            ext_i[k, 0] = now[j]
            ext_i[k, 1] = 0
            ext_i[k, 2] = first_id + k
            ext_f[k, 0] = now_bnd[j, 0]
            ext_f[k, 1] = now_bnd[j, 1]
            k += 1
            prev[w, j] = now[j]
        prev_n[w] = n
    ext_ptr[rows.shape[0]] = k
    cfg = b.cfg
    cfg[K.CFG_T] = t
    status, w_first = K.step_worlds(*((cfg, 0) + b.before + (ext_ptr, ext_i, ext_f) + b.after))
    b.out[4][0] = w_first
    if status == STATUS_OK:
        read_batch(b)
    return status


@njit(cache=True)
def read_batch(b):  # noqa: ANN001, ANN201
    """fused.read_step for every world: its index parts, reward table sums, ends and mask."""
    part_ptr, part_atoms, table_atoms, table_values, table_agent, term_atoms, trunc_atoms, mask_atoms = b.reads
    index, rewards, res, mask, _ = b.out
    lower = b.lower
    for w in range(lower.shape[0]):
        for p in range(len(part_ptr) - 1):
            index[w, p] = -1
            for j in range(part_ptr[p], part_ptr[p + 1]):
                if lower[w, part_atoms[j]] == 1.0:
                    index[w, p] = j - part_ptr[p]
                    break
        rewards[w, :] = 0.0
        for j in range(len(table_atoms)):
            if lower[w, table_atoms[j]] == 1.0:
                rewards[w, table_agent[j]] += table_values[j]
        res[w, 0] = 0.0
        for a in term_atoms:
            if lower[w, a] == 1.0:
                res[w, 0] = 1.0
        res[w, 1] = 0.0
        for a in trunc_atoms:
            if lower[w, a] == 1.0:
                res[w, 1] = 1.0
        for j in range(len(mask_atoms)):
            mask[w, j] = 1 if lower[w, mask_atoms[j]] == 1.0 else 0


SOURCE_STAMP = _stamp_with_sources(step_batch, (inspect.getmodule(step_batch), K, fused))
_stamp_with_sources(read_batch, (inspect.getmodule(step_batch), K, fused))
