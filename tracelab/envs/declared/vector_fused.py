"""A batch of declared worlds' step as ONE compiled call: each world's step facts to engine rows (grouped
by world, as the kernel reads them), the counting kernel's step of every world, and each world's reads.

The batched twin of fused.py, over the same structref (fused.bind; numba compiles it again for these
shapes). Tables are fused.py's with a world axis where a world has its own: `rows` [W, agents] (each
agent's action row, -1: none), `picks` [W, draws] (-1: not drawn), `prev` [W, cap] / `prev_n` [W] (the
step facts each world's last step set), and the reads' results `index` [W, parts], `rewards` [W, agents],
`ends` bool [2, W] (terminated, truncated: a reader copies a row), `mask` [W, mask atoms]. `now`/`now_bnd` are one world's scratch.

The reads go through a truth table [W, read atoms] (`reads`: read_atoms, truth, part_ptr, table_values,
table_agent, sizes), so that a batch on the lanes kernel (which this call cannot step: the engine steps
it) reads with the same code from Engine.is_true (read_truth).

The step's own Python is one call too (step_worlds): each agent's action to its row, the step's draws
(the categorical draws of fixed probabilities, from each world's block of np_random numbers) and, after the
kernel and the reads, every agent's observation numbers (observe_kernel). A small numpy operation costs a
microsecond or more, and a one-world war.toml step did ~20 of them around a compiled step of ~40 µs.
`batch` (the structref's field): `draws` (int64 [3]: DRAW_UNIFORMS or DRAW_GIVEN, the number of draws, and 1
where the step counts in each world's `steps`, 0 for a step outside the episodes: the starts' steps),
`uniforms` [W, block] and `position` [W] (vector_world._Uniforms' buffer: the next number of world w is
uniforms[w, position[w]]), `cumulative` [draws, values] (padded with +inf) and `sizes` [draws]
(vector_world._CategoricalTable's), `agent_rows` [agents] (agent i's first action row), `rows` [W, agents]
and `picks` [W, groups] (the step's, written here), observe_kernel.ObservationReader.arrays (a tuple), and
`steps` [W] (each world's steps into its episode, counted here with the step: a numpy `+= 1` costs a one-world
step ~2 µs), `clock` (int64 [2]: the engine's t and its next external id, which step_worlds reads here rather than
as arguments: each argument of a call from Python is checked, engine/direct_call.py)."""
from __future__ import annotations

import inspect

import numpy as np
from numba import njit

from tracelab.engine import kernel as K
from tracelab.engine.numba_cache import stamp_with_sources
from tracelab.envs.declared import fused, observe_kernel

STATUS_OK = K.STATUS_OK
DRAW_GIVEN, DRAW_UNIFORMS = 0, 1  # batch's draws[0]: picks written by the caller, or drawn here


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
def draw_rows(batch, actions):  # noqa: ANN001, ANN201
    """The step's rows [W, agents] from actions [W, agents] (-1: none; agent i's action a is row
    agent_rows[i] + a), each world's step counted (draws[2] == 1) and, with DRAW_UNIFORMS, every world's draws from its next numbers, as
    vector_world._CategoricalTable.picks (how many cumulative sums are <= u; past the last, value 0)."""
    draws, uniforms, position, cumulative, sizes = batch[0], batch[1], batch[2], batch[3], batch[4]
    agent_rows, rows, picks, steps = batch[5], batch[6], batch[7], batch[9]
    for w in range(rows.shape[0]):
        for i in range(rows.shape[1]):
            rows[w, i] = actions[w, i] + agent_rows[i] if actions[w, i] >= 0 else -1
        if draws[2] == 1:
            steps[w] += 1
    if draws[0] != DRAW_UNIFORMS:
        return
    for w in range(rows.shape[0]):
        at = position[w]
        for d in range(draws[1]):
            u = uniforms[w, at + d]
            c = 0
            while c < sizes[d] and cumulative[d, c] <= u:
                c += 1
            picks[w, d] = 0 if c == sizes[d] else c
        position[w] = at + draws[1]


@njit(cache=True)
def prepare_batch(tables, ext, batch, actions, first_id):  # noqa: ANN001, ANN201
    """draw_rows and build_rows, for a batch the engine steps itself (the lanes kernel). Returns the rows."""
    draw_rows(batch, actions)
    return build_rows(tables, ext, batch[6], batch[7], first_id)


@njit(cache=True)
def step_worlds(b, actions):  # noqa: ANN001, ANN201
    """On the counting kernel, a whole step at the batch's clock (t, first external id): draw_rows,
    build_rows, the kernel's step of every world, and on STATUS_OK the reads (read_batch) and every agent's
    observation numbers. Returns the kernel's status (b.out[4][0]: the world it paused at)."""
    batch = b.batch
    t, first_id = batch[10][0], batch[10][1]
    draw_rows(batch, actions)
    build_rows(b.tables, b.ext, batch[6], batch[7], first_id)
    ext_ptr, ext_i, ext_f = b.ext
    b.state.cfg[K.CFG_T] = t  # what kernel.fused_step does, without its own copy of the kernel to compile
    status, w_first = K.step_worlds(b.state, np.int64(0), ext_ptr, ext_i, ext_f)
    b.out[4][0] = w_first
    if status == STATUS_OK:
        read_batch(b)
        o = batch[8]
        observe_kernel.observe_lower(b.state.lo, o[0], o[1], o[2], o[3], o[4], o[5], o[6])
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
    true atom (-1: none), per agent the reward table's sum, the ends, the mask. A world truncates also at
    the spec's max_steps (sizes[5], -1: none) of its steps (reads[6]) when it did not terminate."""
    part_ptr, table_values, table_agent, sizes, steps = reads[2], reads[3], reads[4], reads[5], reads[6]
    index, rewards, ends, mask, _ = out
    n_parts, n_table, n_term, n_trunc, limit = sizes[0], sizes[1], sizes[2], sizes[3], sizes[5]
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
        ends[0, w] = False
        for j in range(n_term):
            if truth[w, c + j]:
                ends[0, w] = True
        c += n_term
        ends[1, w] = False
        for j in range(n_trunc):
            if truth[w, c + j]:
                ends[1, w] = True
        if limit >= 0 and steps[w] >= limit and not ends[0, w]:
            ends[1, w] = True
        c += n_trunc
        for j in range(mask.shape[1]):
            mask[w, j] = 1 if truth[w, c + j] else 0


SOURCE_STAMP = stamp_with_sources(step_worlds, (inspect.getmodule(step_worlds), K, fused, observe_kernel))
for _f in (build_rows, read_batch, read_truth, draw_rows, prepare_batch):
    stamp_with_sources(_f, (inspect.getmodule(step_worlds), K, fused, observe_kernel))
