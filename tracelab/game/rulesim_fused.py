"""RuleSim's step as ONE compiled call: actions to fact rows, the counting kernel's step, the read-back's
truth table, read_and_settle and observe_step (docs/benchmarks/history.md, "One call per step").

Each numba call from Python pays for unboxing every array it is given (~0.1-0.2 µs an array; a step
passes ~120). Here the arrays are bound once into a structref (`StepBuffers`, one object to unbox) and
bound again only when the engine replaces one of its arrays (Engine.layout_version). The call does what
RuleSim.step's separate calls do, in the same order, on the same buffers; when the kernel pauses (trace
or schedule room, user functions) or fails, it returns the kernel's status and Python goes on exactly as
before (Engine.finish_fused_step, then the read-back and observations as separate calls).

numba's disk cache checks only the source of the module defining a function, not the callees it
compiles in from other modules (engine/kernel.py, rulesim_kernel.py, observe.py). So the cache stamp
of fused_step is a hash of all four sources: a change in any of them compiles it again.
"""
from __future__ import annotations

import inspect

import numpy as np
from numba import njit
from numba.core import types
from numba.experimental import structref
from numba.extending import overload

from tracelab.engine import kernel as K
from tracelab.engine.numba_cache import stamp_with_sources
from tracelab.engine.kernel import StepState
from tracelab.game import observe as _observe
from tracelab.game import rulesim_kernel as _rk
from tracelab.game.observe import observe_step
from tracelab.game.rulesim_kernel import encode_actions, read_and_settle

STATUS_OK = K.STATUS_OK
STATUS_BAD_ACTION = -1  # an action the scenario does not offer: nothing was changed
# the bound arrays, by field; each is a tuple of arrays (or one array) whose order the call fixes
FIELDS = ("encode", "state", "read_atoms", "truth", "settle", "observe", "res")


@structref.register
class StepBuffersType(types.StructRef):
    def preprocess_fields(self, fields):  # noqa: ANN001, ANN201 (numba's hook)
        return tuple((name, types.unliteral(t)) for name, t in fields)


class StepBuffers(structref.StructRefProxy):
    """The arrays of one RuleSim's fused step, bound once (make it with `bind`)."""


structref.define_boxing(StepBuffersType, StepBuffers)


def _new_buffers(encode, state, read_atoms, truth, settle, observe, res):  # noqa: ANN001
    raise NotImplementedError("compiled code only")


@overload(_new_buffers)
def _new_buffers_impl(encode, state, read_atoms, truth, settle, observe, res):  # noqa: ANN001
    # the struct's type from its fields' types (numba's own define_proxy constructor is not cached)
    typ = StepBuffersType(list(zip(FIELDS, (encode, state, read_atoms, truth, settle, observe, res))))

    def impl(encode, state, read_atoms, truth, settle, observe, res):  # noqa: ANN001
        b = structref.new(typ)
        b.encode = encode
        b.state = state
        b.read_atoms = read_atoms
        b.truth = truth
        b.settle = settle
        b.observe = observe
        b.res = res
        return b
    return impl


@njit(cache=True)
def _make_buffers(encode, state, read_atoms, truth, settle, observe, res):  # noqa: ANN001
    return _new_buffers(encode, state, read_atoms, truth, settle, observe, res)


def bind(encode: tuple, state: StepState, read_atoms: np.ndarray, settle: tuple,
         observe: tuple) -> tuple[StepBuffers, np.ndarray]:
    """The buffers of a fused step. encode: encode_actions' arrays after red and blue, without first_id
    (terminated, truncated, allowed, action_atoms, prev, ext_ptr, ext_i, ext_f: the row buffers, whole);
    state: Engine.fused_binding(); read_atoms: the read-back's atom ids; settle / observe: the
    arguments of read_and_settle after the truth table / of observe_step. Returns the buffers and
    their `res` array (what fused_step reports besides its status)."""
    truth = np.empty((state.lo.shape[0], len(read_atoms)), np.bool_)
    res = np.zeros(2, np.int64)
    return _make_buffers(encode, state, read_atoms, truth, settle, observe, res), res


@njit(cache=True)
def fused_step(b, red, blue, t, first_id):  # noqa: ANN001, ANN201
    """One RuleSim step of every world: STATUS_OK when all of it ran; STATUS_BAD_ACTION (nothing done)
    when an action is not offered; else the kernel's status after the fact rows were made and the kernel
    called (b.res: [world the kernel paused at, rows]): the caller goes on as RuleSim's separate calls do."""
    enc = b.encode
    ext_ptr, ext_i, ext_f = enc[5], enc[6], enc[7]
    k = encode_actions(red, blue, enc[0], enc[1], enc[2], enc[3], enc[4], first_id, ext_ptr, ext_i, ext_f)
    b.res[1] = k
    if k < 0:
        return STATUS_BAD_ACTION
    status, w_first = K.fused_step(b.state, t, ext_ptr, ext_i, ext_f)
    b.res[0] = w_first
    if status != STATUS_OK:
        return status
    K.gather_truth(b.state.lo, b.read_atoms, 1.0, b.truth)
    read_and_settle(b.truth, *b.settle)
    observe_step(*b.observe)
    return status


SOURCE_STAMP = stamp_with_sources(fused_step, (inspect.getmodule(bind), K, _rk, _observe))
