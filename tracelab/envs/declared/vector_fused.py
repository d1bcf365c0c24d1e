"""A batch of declared worlds' step as ONE compiled call: each world's step facts to engine rows (grouped
by world, as the kernel reads them), the counting kernel's step of every world, and each world's reads.

The batched twin of fused.py, over the same structref (fused.bind; numba compiles it again for these
shapes). Tables are fused.py's with a world axis where a world has its own: `rows` [W, agents] (each
agent's action row, -1: none), `picks` [W, draws] (-1: not drawn), `prev` [W, cap] / `prev_n` [W] (the
step facts each world's last step set), and the reads' results `index` [W, parts], `rewards` [W, agents],
`res` [W, 2] (terminated, truncated), `mask` [W, mask atoms]. `now`/`now_bnd` are one world's scratch.

The reads go through a truth table [W, read atoms] (`reads`: read_atoms, truth, part_ptr, table_values,
table_agent, sizes), so that a batch on the lanes kernel (which this call cannot step: the engine steps
it) reads with the same code from Engine.is_true (read_truth)."""
from __future__ import annotations

import inspect

from numba import njit

from tracelab.engine import kernel as K
from tracelab.engine.numba_cache import stamp_with_sources
from tracelab.envs.declared import fused

STATUS_OK = K.STATUS_OK


@njit(cache=True)
def build_rows(tables, ext, rows, picks, first_id):  # noqa: ANN001, ANN201
    """The external rows of every world's step, grouped by world (ext: ptr, rows, bounds): world w's
    action rows rows[w] and draws picks[w], and its last step's facts not set again as [0,0]."""
    prev, prev_n = tables[7], tables[8]
    ext_ptr, ext_i, ext_f = ext
    k = 0
    for w in range(rows.shape[0]):
        ext_ptr[w] = k
        k = fused.world_fact_rows(tables, prev[w], prev_n, w, rows[w], picks[w], ext_i, ext_f, first_id, k)
    ext_ptr[rows.shape[0]] = k
    return k


@njit(cache=True)
def step_batch(b, rows, picks, t, first_id):  # noqa: ANN001, ANN201
    """On the counting kernel: build_rows, the kernel's step of every world, and on STATUS_OK the reads
    (read_batch). Returns the kernel's status (b.out[4][0]: the world it paused at)."""
    build_rows(b.tables, b.ext, rows, picks, first_id)
    ext_ptr, ext_i, ext_f = b.ext
    status, w_first = K.fused_step(b.state, t, ext_ptr, ext_i, ext_f)
    b.out[4][0] = w_first
    if status == STATUS_OK:
        read_batch(b)
    return status


@njit(cache=True)
def read_batch(b):  # noqa: ANN001, ANN201
    """The reads of every world from the counting kernel's bounds."""
    read_atoms, truth = b.reads[0], b.reads[1]
    K.gather_truth(b.state.lo, read_atoms, 1.0, truth)
    read_truth(truth, b.reads, b.out)


@njit(cache=True)
def read_truth(truth, reads, out):  # noqa: ANN001, ANN201
    """fused.read_step for every world, from truth [W, read atoms] (columns: the index parts' atoms, the
    reward table's, the terminated, truncated and mask atoms): per index part the position of its first
    true atom (-1: none), per agent the reward table's sum, the ends, the mask."""
    part_ptr, table_values, table_agent, sizes = reads[2], reads[3], reads[4], reads[5]
    index, rewards, res, mask, _ = out
    n_parts, n_table, n_term, n_trunc = sizes[0], sizes[1], sizes[2], sizes[3]
    for w in range(truth.shape[0]):
        for p in range(len(part_ptr) - 1):
            index[w, p] = -1
            for j in range(part_ptr[p], part_ptr[p + 1]):
                if truth[w, j]:
                    index[w, p] = j - part_ptr[p]
                    break
        rewards[w, :] = 0.0
        c = n_parts
        for j in range(n_table):
            if truth[w, c + j]:
                rewards[w, table_agent[j]] += table_values[j]
        c += n_table
        res[w, 0] = 0.0
        for j in range(n_term):
            if truth[w, c + j]:
                res[w, 0] = 1.0
        c += n_term
        res[w, 1] = 0.0
        for j in range(n_trunc):
            if truth[w, c + j]:
                res[w, 1] = 1.0
        c += n_trunc
        for j in range(mask.shape[1]):
            mask[w, j] = 1 if truth[w, c + j] else 0


SOURCE_STAMP = stamp_with_sources(step_batch, (inspect.getmodule(step_batch), K, fused))
for _f in (build_rows, read_batch, read_truth):
    stamp_with_sources(_f, (inspect.getmodule(step_batch), K, fused))
