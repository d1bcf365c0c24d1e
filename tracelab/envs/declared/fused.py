"""A declared world's step as ONE compiled call: the step's facts to engine rows, the counting kernel's
step, and the reads (observation indices, the reward table, the ends, the action mask).

Why: a numba call from Python unboxes every array it is given (~0.5 µs each on this machine); the
counting kernel's step takes ~60 arrays, so calling it from Python costs ~40 µs, more than the step's
work on a toy-text game. So the arrays are bound once into a structref (one object to unbox) and bound again only when the engine replaces one of
its arrays (Engine.layout_version). When the kernel pauses (trace or schedule room) or fails, the call
returns its status and Python goes on with Engine.finish_fused_step, then `read_step`.

Tables (int64 unless said): `act_ptr`/`act_atoms`/`act_bnd` (float64 [n, 2]): each (agent, action)
row's facts (row agent * n_actions + action);
`val_ptr`/`val_atoms`/`val_bnd`: each value's facts, draws' values numbered one after another
(`draw_base[d]` is draw d's value 0); `prev`/`prev_n`: the step facts set by the last engine step;
`now`/`now_bnd`: scratch for this step's. Reads (`reads`) and their results (`out`): read_step. `batch`: a batch's own arrays (vector_fused.py: the step's draws and the
observation), an empty tuple for one world."""
from __future__ import annotations

import inspect
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit
from numba.core import types
from numba.experimental import structref
from numba.extending import overload

from tracelab.engine import kernel as K
from tracelab.engine import numba_python
from tracelab.engine.direct_call import DirectCall
from tracelab.engine.numba_cache import stamp_with_sources
from tracelab.engine.kernel import StepState

if TYPE_CHECKING:
    from tracelab.engine import Engine

STATUS_OK = K.STATUS_OK
FIELDS = ("state", "tables", "ext", "reads", "out", "batch")


@structref.register
class DeclaredBuffersType(types.StructRef):
    def preprocess_fields(self, fields):  # noqa: ANN001, ANN201 (numba's hook)
        return tuple((name, types.unliteral(t)) for name, t in fields)


class DeclaredBuffers(structref.StructRefProxy):
    """The arrays of one declared world's fused step (make it with `bind`)."""


structref.define_boxing(DeclaredBuffersType, DeclaredBuffers)


def _new_buffers(state, tables, ext, reads, out, batch):  # noqa: ANN001
    """The buffers as a plain object, for the kernels run as Python (engine/numba_python.py); compiled code
    takes the overload below."""
    return SimpleNamespace(state=state, tables=tables, ext=ext, reads=reads, out=out, batch=batch)


@overload(_new_buffers)
def _new_buffers_impl(state, tables, ext, reads, out, batch):  # noqa: ANN001
    typ = DeclaredBuffersType(list(zip(FIELDS, (state, tables, ext, reads, out, batch))))

    def impl(state, tables, ext, reads, out, batch):  # noqa: ANN001
        b = structref.new(typ)
        b.state = state
        b.tables = tables
        b.ext = ext
        b.reads = reads
        b.out = out
        b.batch = batch
        return b
    return impl


@njit(cache=True)
def _make_buffers(state, tables, ext, reads, out, batch):  # noqa: ANN001
    return _new_buffers(state, tables, ext, reads, out, batch)


def bind(state: StepState, tables: tuple, ext: tuple, reads: tuple, out: tuple, batch: tuple = ()) -> DeclaredBuffers:
    """The buffers of a fused step over Engine.fused_binding()'s step state."""
    return _make_buffers(state, tables, ext, reads, out, batch)


class FusedBinding:
    """A declared world's fused-step buffers over its engine, bound again whenever the engine's layout
    changes (a regrounding moves the kernel's arrays). One world (world.py) and a batch (vector_world.py)
    keep one each; their tables, rows, reads and outputs are allocated once, before the first bind."""

    def __init__(self, engine: Engine, tables: tuple, ext: tuple, reads: tuple, out: tuple, batch: tuple = ()) -> None:
        self._engine = engine
        self._arrays = (tables, ext, reads, out, batch)
        self._buffers: DeclaredBuffers | None = None
        self._layout = -1  # the engine's layout_version the buffers were bound for
        self._generation = -1  # and numba_python.generation(): kernels compiled or run as Python
        self._calls: dict[Any, DirectCall] = {}  # empty while the kernels run as Python

    def buffers(self) -> DeclaredBuffers:
        """The buffers for the next fused step (grounds what is new first, as Engine.step() does)."""
        if self._engine.prepare_fused_step() != self._layout or numba_python.generation() != self._generation:
            self._buffers = bind(self._engine.fused_binding(), *self._arrays)
            self._layout, self._generation = self._engine.layout_version, numba_python.generation()
            self._calls.clear()
        assert self._buffers is not None
        return self._buffers

    def call(self, dispatcher: Any, *args: Any) -> Any:
        """dispatcher(buffers(), *args), past numba's per-call dispatch (engine/direct_call.py: typing the
        buffers' arrays cost ~2 µs a call)."""
        buffers = self.buffers()
        call = self._calls.get(dispatcher)
        if call is None:
            if numba_python.running_as_python():
                return dispatcher(buffers, *args)
            call = self._calls[dispatcher] = DirectCall(dispatcher, buffers)
        return call(*args)


@njit(cache=True)
def world_fact_rows(tables, prev, prev_n, w, actions, picks, ext_i, ext_f, first_id, k):  # noqa: ANN001, ANN201
    """World w's external fact rows of a step, from row k of (ext_i, ext_f): the facts of each action
    row in `actions` (-1: none) and of each draw's picked value (picks[d] >= 0), and the facts the world
    set last step that are not set again, now [0,0]; `prev` (that world's row) and prev_n[w] then hold
    this step's. Returns the next free row."""
    act_ptr, act_atoms, act_bnd, draw_base, val_ptr, val_atoms, val_bnd, _, _, now, now_bnd = tables
    n = 0
    for action in actions:
        if action < 0:
            continue
        for j in range(act_ptr[action], act_ptr[action + 1]):
            now[n] = act_atoms[j]
            now_bnd[n, 0] = act_bnd[j, 0]
            now_bnd[n, 1] = act_bnd[j, 1]
            n += 1
    for d in range(len(picks)):
        if picks[d] >= 0:
            v = draw_base[d] + picks[d]
            for j in range(val_ptr[v], val_ptr[v + 1]):
                now[n] = val_atoms[j]
                now_bnd[n, 0] = val_bnd[j, 0]
                now_bnd[n, 1] = val_bnd[j, 1]
                n += 1
    for i in range(prev_n[w]):  # last step's facts that are not set again: false now
        again = False
        for j in range(n):
            if now[j] == prev[i]:
                again = True
                break
        if not again:
            ext_i[k, 0] = prev[i]
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
        prev[j] = now[j]
    prev_n[w] = n
    return k


@njit(cache=True)
def fused_step(b, actions, picks, t, first_id):  # noqa: ANN001, ANN201
    """Set the facts of each action row in `actions` (-1: none) and, per draw d with picks[d] >= 0, the
    facts of its value picks[d]; the last step's facts not set again become [0,0]. Steps the kernel; on
    STATUS_OK also reads (read_step). Returns the kernel's status (b.out[4][0]: the world it paused at)."""
    prev, prev_n = b.tables[7], b.tables[8]
    ext_ptr, ext_i, ext_f = b.ext
    k = world_fact_rows(b.tables, prev, prev_n, 0, actions, picks, ext_i, ext_f, first_id, 0)
    ext_ptr[0] = 0
    ext_ptr[1] = k
    b.state.cfg[K.CFG_T] = t  # K.fused_step's work, without its own copy of the kernel to compile
    status, w_first = K.step_worlds(b.state, np.int64(0), ext_ptr, ext_i, ext_f)
    b.out[4][0] = w_first
    if status == STATUS_OK:
        read_step(b)
    return status


@njit(cache=True)
def read_step(b):  # noqa: ANN001, ANN201
    """After a step: per (agent, index part) the index of its first true atom (-1: none), per agent the
    reward table's sum, whether a terminated / truncated atom is true, the mask (1 where the atom is
    [1,1]), and, where a recorder keeps them (keep_terms[0] == 1), each reward term's quantity [agent *
    term]: a table atom's truth (1 where its lower bound is 1), a scaled atom's lower bound (the reward
    atoms are read here anyway: in Python the read cost a traced step ~1-2 us, docs/benchmarks.md)."""
    part_ptr, part_atoms, table_atoms, table_values, table_agent, term_atoms, trunc_atoms, mask_atoms, \
        reward_atoms, reward_is_table, keep_terms = b.reads
    index, rewards, res, mask, _, quantities = b.out
    lower = b.state.lo
    for p in range(len(part_ptr) - 1):
        index[p] = -1
        for j in range(part_ptr[p], part_ptr[p + 1]):
            if lower[0, part_atoms[j]] == 1.0:
                index[p] = j - part_ptr[p]
                break
    rewards[:] = 0.0
    for j in range(len(table_atoms)):
        if lower[0, table_atoms[j]] == 1.0:
            rewards[table_agent[j]] += table_values[j]
    res[0] = 0.0
    for a in term_atoms:
        if lower[0, a] == 1.0:
            res[0] = 1.0
    res[1] = 0.0
    for a in trunc_atoms:
        if lower[0, a] == 1.0:
            res[1] = 1.0
    for j in range(len(mask_atoms)):
        mask[j] = 1 if lower[0, mask_atoms[j]] == 1.0 else 0
    if keep_terms[0] == 1:
        for j in range(len(reward_atoms)):
            bound = lower[0, reward_atoms[j]]
            quantities[j] = (1.0 if bound == 1.0 else 0.0) if reward_is_table[j] == 1 else bound


SOURCE_STAMP = stamp_with_sources(fused_step, (inspect.getmodule(bind), K))
stamp_with_sources(read_step, (inspect.getmodule(bind), K))


def csr(groups: list[np.ndarray], bounds: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ptr, atoms, bounds [n, 2]) of a list of atom groups."""
    ptr = np.zeros(len(groups) + 1, np.int64)
    ptr[1:] = np.cumsum([len(g) for g in groups])
    atoms = np.concatenate([np.zeros(0, np.int64), *groups]).astype(np.int64)
    bnd = np.concatenate([np.zeros((0, 2)), *bounds]).astype(np.float64).reshape(-1, 2)
    return ptr, atoms, bnd
