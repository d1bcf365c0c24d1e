"""RuleSim's step as one compiled call (rulesim_fused) against the separate calls (fused=False): the same
states, rewards, observations and trace rows, including steps whose kernel call pauses (the trace buffer
full) so that the fallback runs, resets, errors, and the cache stamp over the callees' sources."""
from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

from tracelab.bench.sims import scenario_for
from tracelab.engine import kernel as K
from tracelab.game import observe, rulesim_fused, rulesim_kernel
from tracelab.game.rulesim import RuleSim


def _pair(agents: int, worlds: int, **kw: object) -> tuple[RuleSim, RuleSim]:
    sc = scenario_for(agents)
    return (RuleSim(sc, worlds, seed=3, trace=True, kernel="counting", fused=True, **kw),
            RuleSim(sc, worlds, seed=3, trace=True, kernel="counting", fused=False, **kw))


def _same_result(ra: object, rb: object, step: int) -> None:
    for f in dataclasses.fields(ra):
        x, y = getattr(ra, f.name), getattr(rb, f.name)
        assert x.dtype == y.dtype and np.array_equal(x, y), (step, f.name)


def _fill_trace(sim: RuleSim) -> None:
    """The engine's trace buffer full up to one row (zero rows, the same in both simulators): the next
    traced step's kernel call stops for room and Python goes on (CountingState.finish)."""
    eng = sim.engine
    n = int(eng._tr_n[0])  # noqa: SLF001 (the tests set up the pause)
    eng._tri[n:] = 0  # noqa: SLF001
    eng._trf[n:] = 0.0  # noqa: SLF001
    eng._tr_n[0] = eng._tri.shape[0] - 1  # noqa: SLF001


def _same_rows(ta: dict[str, np.ndarray], tb: dict[str, np.ndarray], step: int) -> None:
    assert list(ta) == list(tb)
    for k in ta:
        assert ta[k].dtype == tb[k].dtype and np.array_equal(ta[k], tb[k]), (step, k)


@pytest.mark.parametrize("agents,worlds,stack", [(1, 1, False), (1, 3, True), (5, 2, False)])
def test_fused_steps_equal_separate_calls(agents: int, worlds: int, stack: bool) -> None:
    a, b = _pair(agents, worlds, stack_previous=stack)
    rng = np.random.default_rng(agents * 10 + worlds)
    ids = np.asarray(a.scenario.action_ids)
    paused = 0
    for i in range(160):
        red = rng.choice(ids, (worlds, agents))
        if i in (20, 90):
            _fill_trace(a)
            _fill_trace(b)
        version = a.engine.layout_version
        ra, rb = a.step(red, a.scripted_actions("blue")), b.step(red, b.scripted_actions("blue"))
        paused += a.engine.layout_version != version  # a buffer grew: the kernel paused, Python went on
        _same_result(ra, rb, i)
        assert np.array_equal(a.allowed_actions(), b.allowed_actions())
        if i % 40 < 30:  # otherwise the trace piles up over several steps
            _same_rows(a.take_trace(), b.take_trace(), i)
        done = ra.terminated | ra.truncated
        if done.any():
            _same_rows({"obs": a.reset(worlds=done)}, {"obs": b.reset(worlds=done)}, i)
    _same_rows(a.take_trace(), b.take_trace(), -1)
    assert a.fused and a._bound is not None and not b.fused
    assert paused >= 2  # the slow path ran (trace buffer grown mid-step)
    assert a.engine.t == b.engine.t and a.engine.next_external_id() == b.engine.next_external_id()
    assert np.array_equal(a.engine.lower, b.engine.lower) and np.array_equal(a.engine.upper, b.engine.upper)


def test_trace_overflow_step_runs_the_fallback_and_matches() -> None:
    """The kernel stops for trace room within the fused call: the step is finished by the separate calls."""
    a, b = _pair(1, 1)
    _fill_trace(a)
    _fill_trace(b)
    red = np.array([[1]])
    calls = []
    finish = a.engine._state.finish  # noqa: SLF001

    def spy(status: int, *rest: object) -> int:
        calls.append(status)
        return finish(status, *rest)
    a.engine._state.finish = spy  # noqa: SLF001
    ra, rb = a.step(red, np.array([[2]])), b.step(red, np.array([[2]]))
    assert calls == [K.STATUS_TRACE_ROOM]
    _same_result(ra, rb, 0)
    _same_rows(a.take_trace(), b.take_trace(), 0)
    _same_result(a.step(red, np.array([[0]])), b.step(red, np.array([[0]])), 1)  # bound again, fused


def test_bad_action_raises_and_changes_nothing() -> None:
    a, b = _pair(1, 1)
    before = a.engine.t, a.engine.next_external_id(), a.state.pos.copy()
    with pytest.raises(ValueError, match="not offered"):
        a.step(np.array([[99]]), np.array([[0]]))
    assert (a.engine.t, a.engine.next_external_id()) == before[:2] and np.array_equal(a.state.pos, before[2])
    _same_result(a.step(np.array([[1]]), np.array([[0]])), b.step(np.array([[1]]), np.array([[0]])), 0)


def test_other_kernels_take_separate_calls() -> None:
    sim = RuleSim(scenario_for(1), 1, seed=0, trace=False, kernel="lanes")
    sim.step(np.array([[0]]), np.array([[0]]))
    assert not sim.fused and sim.engine.kernel == "lanes"


def test_cache_stamp_covers_the_callees_sources() -> None:
    """numba stamps a cache with the defining file only; fused_step's stamp hashes its callees' too."""
    import hashlib
    digest = hashlib.sha256()
    for m in (rulesim_fused, K, rulesim_kernel, observe):
        digest.update(inspect.getsource(m).encode() + b"\0")
    assert rulesim_fused.SOURCE_STAMP == digest.digest()
    assert rulesim_fused.fused_step._cache._cache_file._source_stamp == digest.digest()  # noqa: SLF001


@pytest.mark.parametrize("handover", [False, True])
def test_local_trace_columns_equal_the_python_path(handover: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """Engine.take_trace(t_start, episode) in one compiled call (or, for a step of TRACE_HANDOVER_ROWS
    rows, the handed-over buffers localised in numpy): the columns the plain take_trace() and the episode
    clock in Python give (the store's rows)."""
    from tracelab.engine import Engine, core
    if handover:
        monkeypatch.setattr(core, "TRACE_HANDOVER_ROWS", 1)
    from tracelab.engine.core import TRACE_LOCAL_COLUMNS
    from tracelab.game.facts import scenario_program
    sc = scenario_for(1)
    engines = [Engine(scenario_program(sc), worlds=3, trace=True, kernel="counting") for _ in range(2)]
    t_start = np.array([0, 2, 5], np.int64)
    episode = np.array([0, 4, 7], np.int64)
    for step in range(4):
        for e in engines:
            e.step()
        version = engines[1].layout_version
        plain, local = engines[0].take_trace(), engines[1].take_trace(t_start, episode)
        assert (engines[1].layout_version != version) == handover  # handed-over buffers are replaced
        world = plain["world"].astype(np.int64)
        plain["t"] = (plain["t"] - t_start[world]).astype(np.int32)
        plain["world_episode"] = episode[world]
        assert tuple(local) == TRACE_LOCAL_COLUMNS and len(plain["t"]) > 0
        _same_rows(local, plain, step)


def test_facts_queued_on_the_engine_are_refused_as_by_separate_calls() -> None:
    a, b = _pair(1, 1)
    for sim in (a, b):
        sim.engine.add_facts(sim._action_atoms[:1, :1].ravel(), 1.0, 1.0)  # noqa: SLF001
        with pytest.raises(RuntimeError, match="queued by add_fact"):
            sim.step(np.array([[0]]), np.array([[0]]))


def test_strided_or_read_only_actions_take_the_compiled_signature() -> None:
    """Actions as a column of a bigger array or a read-only view: copied to the one signature the
    compiled step has (another layout would compile it again), with the same result."""
    a, b = _pair(1, 2)
    before = len(rulesim_fused.fused_step.signatures)
    wide = np.array([[1, 9], [3, 9]], np.int64)[:, :1]  # not C-contiguous
    ro = np.array([[2], [0]], np.int64)
    ro.flags.writeable = False
    _same_result(a.step(wide, ro), b.step(wide.copy(), ro.copy()), 0)
    assert len(rulesim_fused.fused_step.signatures) == max(before, 1)
