"""engine.direct_call: the kernel's step called past numba's dispatch, never with machine code compiled for
other argument types."""
from __future__ import annotations

import numpy as np
from numba import njit

from tracelab.engine import Engine, parse_program
from tracelab.engine.direct_call import DirectCall

CHAIN = """
edge(a,b) static
edge(b,c) static
spread: reach(Y) <-1 reach(X), edge(X,Y)
"""


@njit
def _weighted_sum(record, x):
    return record[0][0] * x.sum() + record[1][0]


def test_a_call_of_other_argument_types_goes_through_the_dispatcher():
    record = (np.array([2.0]), np.array([1], np.int64))
    call = DirectCall(_weighted_sum, record)
    assert call(np.array([1, 2], np.int64)) == 7.0
    assert call.resolved
    assert call(np.array([3, 4], np.int64)) == 15.0  # the int64 entry point
    # float64 read as int64 machine code would be garbage: the new type is dispatched (compiled) and resolved
    assert call(np.array([0.25, 0.5])) == 2.5
    assert call(np.array([1, 1], np.int64)) == 5.0
    assert len(_weighted_sum.signatures) == 2


def test_engine_step_calls_the_kernel_past_dispatch_and_rebinds_when_a_buffer_is_replaced():
    own, direct = (Engine(parse_program(CHAIN), kernel="counting", trace=True) for _ in range(2))
    for eng in (own, direct):
        eng.add_fact(eng.atom("reach", "a"))
    direct.step()
    call = direct._state._step_call
    assert call is not None and call.resolved and call.record is direct.fused_binding()
    direct._grow_trace(4 * direct._tri.shape[0])  # the record is rebuilt: the call binds the new one
    direct.run(2)
    assert direct._state._step_call is not call and direct._state._step_call.record.tri is direct._tri
    own.run(3)
    assert direct.interpretation(0) == own.interpretation(0)
    assert direct.query("reach(c)", 0) == (1.0, 1.0)
    assert direct.trace_rows_waiting == own.trace_rows_waiting > 0
