"""The tables grounding hands the kernels (engine/kernel_tables.py): named and frozen, each field of the
dtype and shape its comment says (the numba kernels are compiled for those dtypes: another one would
compile them again), and the CSR indexes consistent with the arrays they index."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from tracelab.engine import Engine, parse_program
from tracelab.engine.kernel_tables import AggregateTables, KernelTables

# every kind of rule: delayed, ordinary, immediate, and two aggregated ones (a quantifier, a function);
# a `~` clause, a bounded clause and a %closed predicate
PROGRAM = """
%closed blocked
edge(a,b) static
edge(b,c) static
edge(a,c) static
reach(a)
risk(c):[0.2,0.6]
spread: reach(Y) <-1 reach(X), edge(X,Y), ~blocked(Y)
mark:   seen(X) <-0 reach(X)
stop:   blocked(X) <-! seen(X), edge(X,c)
most:   hub(X) <-0 edge(X,Y), [>= 50%] reach(Y)
worst:  r(X):average <-0 edge(X,Y), risk(Y):[0,1]
"""

KERNEL_DTYPES = {"inst": (np.int32, 2), "wc_ptr": (np.int32, 1), "wc_bnd": (np.float64, 2),
                 "wc_flags": (np.uint8, 1), "wc_code": (np.uint8, 1), "wc_gptr": (np.int32, 1),
                 "wg": (np.int32, 1), "ih_ptr": (np.int32, 1), "ih_inst": (np.int32, 1), "b_ptr": (np.int32, 1),
                 "b_atom": (np.int32, 1), "b_flags": (np.uint8, 1), "b_bnd": (np.float64, 2),
                 "b_code": (np.uint8, 1)}
AGGREGATE_DTYPES = {"ag_rule": (np.int64, 2), "ag_cf": (np.float64, 3), "ag_cn": (np.uint8, 2),
                    "ag_q": (np.int64, 2), "ag_qv": (np.float64, 1), "hg_i": (np.int64, 2),
                    "hg_ptr": (np.int64, 1), "je_g": (np.int64, 1), "je_body": (np.int64, 2)}


def built() -> tuple[Engine, KernelTables, AggregateTables]:
    eng = Engine(parse_program(PROGRAM), kernel="counting")
    eng.step()
    kt, agg = eng._kt, eng._agg
    assert isinstance(kt, KernelTables) and isinstance(agg, AggregateTables)
    return eng, kt, agg


def test_every_field_has_the_dtype_and_rank_the_kernels_are_compiled_for() -> None:
    _, kt, agg = built()
    for tables, dtypes in ((kt, KERNEL_DTYPES), (agg, AGGREGATE_DTYPES)):
        assert {f.name for f in dataclasses.fields(tables)} >= set(dtypes)
        for name, (dtype, ndim) in dtypes.items():
            a = getattr(tables, name)
            assert (a.dtype, a.ndim) == (np.dtype(dtype), ndim), name
            assert a.flags.c_contiguous, name
    for name in ("gather_cap", "request_cap", "user_gather_cap"):
        assert isinstance(getattr(agg, name), int) and getattr(agg, name) >= 1


def test_the_csr_indexes_and_the_shapes_agree() -> None:
    eng, kt, agg = built()
    n_atoms, n_inst = eng.vocab.n_atoms, len(kt.inst)
    assert n_inst and len(agg.hg_i)  # the program grounds rules of every kind
    assert kt.inst.shape == (n_inst, 4)
    assert len(kt.wc_ptr) == len(kt.ih_ptr) == n_atoms + 1
    n_classes = int(kt.wc_ptr[-1])
    assert len(kt.wc_bnd) == len(kt.wc_flags) == len(kt.wc_code) == len(kt.wc_gptr) - 1 == n_classes
    assert int(kt.wc_gptr[-1]) == len(kt.wg) == len(kt.b_atom)  # every binding clause watches once
    assert len(kt.b_ptr) == n_inst + 1 and int(kt.b_ptr[-1]) == len(kt.b_atom)
    assert len(kt.b_flags) == len(kt.b_bnd) == len(kt.b_code) == len(kt.b_atom)
    assert int(kt.ih_ptr[-1]) == len(kt.ih_inst) >= 1  # `stop` is immediate
    assert kt.wc_flags.any() and kt.b_flags.any()  # `~blocked`, and blocked is %closed
    assert len(agg.ag_rule) == 2 and len(agg.ag_q) == len(agg.ag_qv) == 1
    assert agg.ag_cf.shape[:2] == agg.ag_cn.shape and agg.ag_cf.shape[2] == 3
    assert len(agg.hg_ptr) == len(agg.hg_i) + 1 and int(agg.hg_ptr[-1]) == len(agg.je_g) == len(agg.je_body)


def test_the_tables_are_frozen() -> None:
    _, kt, agg = built()
    with pytest.raises(dataclasses.FrozenInstanceError):
        kt.inst = kt.inst[:0]  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        agg.gather_cap = 0  # type: ignore[misc]
    with pytest.raises((AttributeError, TypeError)):  # slots: no field can be added by a typo
        object.__setattr__(kt, "wc_cod", kt.wc_code)
