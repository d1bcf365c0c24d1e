"""The lanes kernel (engine/lanes.py) against the counting kernel on batches wider than one machine word.

tests/test_engine_vs_reference.py checks both kernels against the reference evaluator with two worlds;
here random crisp programs run in 70 and 130 worlds (two and three words, the last one partly used) with
different external facts per world and random per-world restores, and every step must give the same
bounds, the same trace rows in the same order, the same pending firings and the same statistics.
"""
from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from strategies import Scenario, scenarios
from tracelab.engine import Engine, parse_program
from tracelab.engine.errors import FixpointError, InconsistencyError
from tracelab.engine.program import INCONSISTENCY_POLICIES

SCALE = float(os.environ.get("TRACELAB_EXAMPLES", "1"))
SEMANTIC_STATS = ("firings", "rederivations", "static_ignored", "changes", "passes")


def assert_same(a: Engine, b: Engine, t: int) -> None:
    np.testing.assert_array_equal(a.lower, b.lower, err_msg=f"lower at t={t}")
    np.testing.assert_array_equal(a.upper, b.upper, err_msg=f"upper at t={t}")
    np.testing.assert_array_equal(a.static, b.static, err_msg=f"static at t={t}")
    atoms = np.arange(a.lower.shape[1])  # the truth tables of read-back, [worlds, atoms]
    for eng in (a, b):
        np.testing.assert_array_equal(eng.is_true(atoms), a.lower == 1.0, err_msg=f"is_true at t={t}")
        np.testing.assert_array_equal(eng.is_false(atoms), a.upper == 0.0, err_msg=f"is_false at t={t}")
    # what `%inconsistency abort` names as an atom's old source (lanes: resolved through restores)
    np.testing.assert_array_equal(a._state.last_cause, b._state.last_cause, err_msg=f"last causes at t={t}")
    ta, tb = a.take_trace(), b.take_trace()
    for col in ta:
        np.testing.assert_array_equal(ta[col], tb[col], err_msg=f"trace column {col} at t={t}")
    sa, sb = a.stats, b.stats
    for name in SEMANTIC_STATS:
        np.testing.assert_array_equal(sa[name], sb[name], err_msg=f"stats {name} at t={t}")
    for w in range(a.n_worlds):
        assert sorted(a.pending(w)) == sorted(b.pending(w)), f"pending of world {w} at t={t}"


def _world_of(message: str) -> str:
    return message.split("(world ")[-1].split(")")[0]


def _comparable(error: str | None) -> str | None:
    """An error as both kernels must report it. A FixpointError's tail (which atoms kept changing) is read
    from the trace rows the kernel has written when it stops, which the two kernels need not have written
    alike by then: where and when must agree, not that explanation."""
    if error is None or not error.startswith("FixpointError"):
        return error
    return ": ".join(error.split(": ")[:2])


def run_pair(sc: Scenario, worlds: int, seed: int, threads: int) -> None:
    rng = np.random.default_rng(seed)
    kw = dict(worlds=worlds, max_passes=40, max_immediate=200,
              trace=rng.random(worlds) < 0.7)  # some worlds untraced
    a = Engine(sc.program, sc.graph, kernel="counting", **kw)
    b = Engine(sc.program, sc.graph, kernel="lanes", threads=threads, **kw)
    facts = [f for step in sc.world_externals[0] for f in step] if sc.world_externals else []
    snaps: list[tuple[dict, dict]] = []
    for t in range(sc.steps + 3):
        # external facts: each one in a random subset of worlds
        for f in facts:
            where = np.flatnonzero(rng.random(worlds) < 0.3)
            for eng in (a, b):
                eng.add_facts(np.full(len(where), eng.atom(f.pred, *f.args)), f.lower, f.upper, where,
                              f.static)
        errors = []
        for eng in (a, b):
            try:
                eng.step()
                errors.append(None)
            except (InconsistencyError, FixpointError) as e:
                errors.append(f"{type(e).__name__}: {e}")
        if errors[0] is None or errors[1] is None or _world_of(errors[0]) == _world_of(errors[1]):
            assert _comparable(errors[0]) == _comparable(errors[1]), \
                f"t={t}: counting raised {errors[0]}, lanes {errors[1]}"
        else:  # several worlds fail: lanes, in lock-step, may meet another world's failure first
            assert errors[0].split(":")[0] == errors[1].split(":")[0], (errors, t)
        if errors[0] is not None:
            return
        assert_same(a, b, t)
        if rng.random() < 0.4:
            snaps.append((a.snapshot(), b.snapshot()))
        if snaps and rng.random() < 0.5:
            sa, sb = snaps[rng.integers(len(snaps))]
            worlds_back = np.flatnonzero(rng.random(worlds) < 0.4)
            a.restore(sa, worlds_back)
            b.restore(sb, worlds_back)
            np.testing.assert_array_equal(a.lower, b.lower, err_msg=f"lower after restore at t={t}")


@settings(max_examples=int(60 * SCALE), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(sc=scenarios(per_world=1, crisp=True, policies=INCONSISTENCY_POLICIES), worlds=st.sampled_from([70, 130]),
       seed=st.integers(0, 2**16), threads=st.sampled_from([1, 2, 3]))
def test_lanes_match_counting_in_wide_batches_with_restores(sc: Scenario, worlds: int, seed: int,
                                                            threads: int) -> None:
    """threads: the batch is cut into that many shards of whole words (at most one per word). Under
    `%inconsistency abort` both must stop with the same message, whose old source may predate a restore."""
    run_pair(sc, worlds, seed, threads)


GAME_LIKE = """
%mode override
start: at(a, c0)
step: at(A, Y) <-! at(A, X), next(X, Y), go(A)
leave: at(A, X):[0,0] <-! at(A, X), next(X, Y), at(A, Y), go(A)
seen: visited(A, X) <-1 at(A, X)
next(c0, c1) static
next(c1, c2) static
next(c2, c3) static
"""


def test_auto_takes_lanes_for_crisp_batches_and_counting_otherwise() -> None:
    prog = parse_program(GAME_LIKE)
    assert Engine(prog, worlds=64).kernel == "lanes"
    # below 64 worlds: the counting kernel, or the compiled one once the compile cache holds this program
    assert Engine(prog, worlds=8).kernel in ("counting", "compiled")
    assert Engine(prog, worlds=8, kernel="lanes").kernel == "lanes"
    half = parse_program(GAME_LIKE + "h: half(A):[0.5,1] <-0 at(A, c1)\n")
    assert Engine(half, worlds=64).kernel == "counting"


def test_lanes_refuses_a_program_that_is_not_crisp_by_name() -> None:
    half = parse_program(GAME_LIKE + "h: half(A):[0.5,1] <-0 at(A, c1)\n", "game.rules")
    with pytest.raises(ValueError, match=r"rule h \(game.rules:\d+(:\d+)?\) sets \[0.5,1\]"):
        Engine(half, worlds=4, kernel="lanes")


def test_a_bound_the_lanes_cannot_hold_moves_the_engine_to_counting_without_losing_state() -> None:
    prog = parse_program(GAME_LIKE)
    a = Engine(prog, worlds=66, kernel="counting")
    b = Engine(prog, worlds=66, kernel="lanes")
    for eng in (a, b):
        eng.add_facts(np.full(33, eng.atom("go", "a")), 1.0, 1.0, np.arange(0, 66, 2))
        eng.run(2)
        eng.add_fact(eng.atom("go", "a"), 0.25, 0.75, world=5)  # not crisp
        eng.add_facts(np.full(66, eng.atom("go", "a")), 1.0, 1.0, np.arange(66))
        eng.step()
    assert b.kernel == "counting"
    assert_same(a, b, 3)
    for eng in (a, b):
        eng.run(2)
    assert_same(a, b, 5)
    assert a.interpretation(0)["visited(a,c3)"] == (1.0, 1.0)


def test_the_two_kernel_modules_spell_their_shared_codes_alike() -> None:
    from tracelab.engine import crisp, kernel, lanes
    for name in lanes.SHARED_CODES:
        assert getattr(lanes, name) == getattr(kernel, name), name
    # the Engine reads bounds as lanes' value codes without importing lanes (engine/crisp.py)
    assert (crisp.V_U, crisp.V_T, crisp.V_F) == (lanes.V_U, lanes.V_T, lanes.V_F)


def test_abort_after_a_restore_names_the_snapshots_cause() -> None:
    """A restore leaves the lanes kernel's last causes alone and counts the world's restores instead; a
    cause older than the restore is then read from the snapshot. The message must be the counting
    kernel's."""
    prog = parse_program("""
    %mode intersection
    %inconsistency abort
    start: p(a) @0..0
    """, file="abort.rules")
    messages = []
    for kernel in ("counting", "lanes"):
        eng = Engine(prog, worlds=3, kernel=kernel)
        eng.add_facts(np.array([eng.atom("p", "a")]), 0.0, 1.0)  # settable from outside (no change)
        eng.step()
        snap = eng.snapshot()
        eng.step()
        eng.restore(snap, np.array([1]))
        eng.add_facts(np.array([eng.atom("p", "a")]), 0.0, 0.0, np.array([1]))
        with pytest.raises(InconsistencyError) as e:
            eng.step()
        messages.append(str(e.value))
    assert messages[0] == messages[1]
    assert "(world 1)" in messages[1] and "came from fact start (abort.rules:4" in messages[1], messages[1]


def test_lanes_ab_calls_another_trees_kernel_with_the_arguments_it_names() -> None:
    """bench.lanes_ab measures a branch's kernel against main's, whose step_lanes may take fewer tables."""
    import types

    from tracelab.bench.lanes_ab import by_name

    def kernel(fn: types.FunctionType) -> types.SimpleNamespace:
        fn.py_func = fn  # type: ignore[attr-defined]  (as a numba dispatcher has it)
        return types.SimpleNamespace(step_lanes=fn)

    mine = kernel(lambda cfg, w0, sent_atom, ctl: None)
    other = kernel(lambda cfg, w0, ctl: (cfg, w0, ctl))
    assert by_name(other, mine).step_lanes(1, 2, "sentinels", 3) == (1, 2, 3)
    assert by_name(mine, mine) is mine
    mine.C_SETTLED, mine.N_CTL, other.N_CTL = 3, 5, 3  # the backend sizes ctl and names its fields by the module's
    assert (by_name(other, mine).C_SETTLED, by_name(other, mine).N_CTL) == (3, 5)


def test_a_step_the_lanes_kernel_finished_leaves_its_worlds_settled() -> None:
    """After a step the lanes kernel finished, no active immediate grounding could change its head (the
    immediate phase ran until none would), so the next step's pass 0 looks only at what its changes push,
    not at every active immediate grounding (lanes.C_SCAN). A restore from a snapshot that was not settled
    and new groundings make it look at them all again; the counting kernel agrees at every step."""
    from tracelab.engine import lanes as L

    prog = parse_program(GAME_LIKE)
    a = Engine(prog, worlds=70, kernel="counting")
    b = Engine(prog, worlds=70, kernel="lanes")
    before_any_step = (a.snapshot(), b.snapshot())
    shard = b._state.shards[0]

    def step(t: int, agent: str = "a") -> int:
        for eng in (a, b):
            eng.add_facts(np.full(35, eng.atom("go", agent)), 1.0, 1.0, np.arange(0, 70, 2))
            if agent != "a":  # a new agent: its groundings are new
                eng.add_facts(np.full(70, eng.atom("at", agent, "c0")), 1.0, 1.0, np.arange(70))
            eng.step()
        assert_same(a, b, t)
        return int(shard.ctl[L.C_SCAN])

    assert [step(t) for t in range(3)] == [1, 0, 0]
    settled = (a.snapshot(), b.snapshot())
    for eng, snap in zip((a, b), before_any_step):
        eng.restore(snap, np.arange(0, 70, 3))
    assert step(3) == 1
    for eng, snap in zip((a, b), settled):
        eng.restore(snap, np.arange(1, 70, 3))
    assert step(4) == 0
    n_groundings = len(shard.gs)
    assert step(5, agent="b") == 1
    assert len(shard.gs) > n_groundings
    assert step(6) == 0
