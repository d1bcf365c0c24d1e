"""The kernel's step state is one record (kernel.StepState), built in one place and rebuilt when a buffer
is replaced: the engine's own step and every fused step read the same arrays through it."""
from __future__ import annotations

import numpy as np

from tracelab.engine import Engine, kernel, parse_program

CHAIN = """
edge(a,b) static
edge(b,c) static
spread: reach(Y) <-1 reach(X), edge(X,Y)
"""


def test_fused_binding_is_the_step_state_over_the_engines_current_buffers():
    eng = Engine(parse_program(CHAIN), kernel="counting", trace=True)
    eng.add_fact(eng.atom("reach", "a"))
    eng.step()
    state = eng.fused_binding()
    assert isinstance(state, kernel.StepState)
    assert state.lo is eng._state.lower and state.tri is eng._tri and state.cfg is eng._cfg
    assert eng.fused_binding() is state  # built once while the layout stays the same
    version = eng.layout_version
    eng._grow_trace(4 * eng._tri.shape[0])  # a buffer replaced: the record is built again over the new one
    assert eng.layout_version != version
    again = eng.fused_binding()
    assert again is not state and again.tri is eng._tri and again.tri.shape[0] > state.tri.shape[0]


def test_fused_hook_steps_as_the_engines_own_step():
    """kernel.step_worlds over the record with the step's t set, as the declared worlds' fused steps call it
    (tracelab/envs/declared/fused.py, vector_fused.py), makes the same interpretation as Engine.step()."""
    own, fused = (Engine(parse_program(CHAIN), kernel="counting") for _ in range(2))
    for eng in (own, fused):
        eng.add_fact(eng.atom("reach", "a"))
    own.run(3)
    fused.step()  # the queued fact goes in through the engine's own step
    empty = (np.zeros(2, np.int64), np.zeros((0, 3), np.int64), np.zeros((0, 2)))
    for _ in range(2):
        fused.prepare_fused_step()
        state = fused.fused_binding()
        state.cfg[kernel.CFG_T] = fused.t
        status, w = kernel.step_worlds(state, np.int64(0), *empty)
        fused.finish_fused_step(status, w, *empty)
    assert fused.t == own.t == 3
    assert fused.interpretation(0) == own.interpretation(0)
    assert fused.query("reach(c)", 0) == (1.0, 1.0)
