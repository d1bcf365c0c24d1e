"""Background compiles (engine/compile_background.py, the child: compile_job.py): Engine(kernel="compiled",
background_compile=True) on a program not yet cached starts on the counting kernel, compiles in a child process,
and switches to the compiled kernel between two steps; the run is exactly the run that never switched. A real
compile of a small program into a temporary cache (numba compiles the whole kernel: tens of seconds of CPU,
once)."""
from __future__ import annotations

import logging
import subprocess
import sys

import numpy as np
import pytest
from tracelab.engine import Engine, parse_program
from tracelab.engine import compile_cache as cc
from tracelab.engine import compile_background

SMALL = """
r1: b(X) <-0 a(X), e(X,Y)
r2: c(Y):[0.2,0.9] <-1 b(X), e(X,Y)
r3: a(Y) <-0 c(Y):[0.5,1]
r4: d(X) <-2 c(X), ~b(X)
a(n1)
e(n1,n2)
e(n2,n3)
e(n3,n1)
"""


def _assert_same(a: Engine, b: Engine, t: int) -> None:
    ta, tb = a.take_trace(), b.take_trace()
    assert ta.keys() == tb.keys()
    for col in ta:
        np.testing.assert_array_equal(ta[col], tb[col], err_msg=f"trace column {col} at t={t}")
    for w in range(a.n_worlds):
        assert a.interpretation(w) == b.interpretation(w), f"world {w} at t={t}"
    for name, col in a.stats.items():
        np.testing.assert_array_equal(col, b.stats[name], err_msg=f"stat {name} at t={t}")
    assert a.pending(1) == b.pending(1)


def _drive(eng: Engine, t: int, snap: dict | None) -> None:
    """External facts that differ by world and step, and a world restored from a snapshot at t = 6."""
    node = f"n{1 + t % 3}"
    eng.add_fact(eng.atom("a", node), 1.0, 1.0, world=t % 2)
    eng.add_fact(eng.atom("b", f"n{1 + (t + 1) % 3}"), 0.0, 0.0, world=1 - t % 2)
    if snap is not None and t == 6:
        eng.restore(snap, np.array([1]))
    eng.step()


def test_a_run_switches_to_the_compiled_kernel_exactly(tmp_path, monkeypatch: pytest.MonkeyPatch,
                                                        caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="tracelab")
    monkeypatch.setenv(cc.CACHE_ENV, str(tmp_path))
    program = parse_program(SMALL)
    switching = Engine(program, worlds=2, kernel="compiled", background_compile=True)
    plain = Engine(program, worlds=2, kernel="counting")
    assert switching.kernel == "counting" and switching.background is not None
    entry = switching.background.entry
    # another run asks for the same kernel at once (`tracelab compile`, the same code path): the entry's
    # lock lets one of the two compile, the other waits and loads what the first cached
    rules = tmp_path / "small.rules"
    rules.write_text(SMALL)
    other = subprocess.Popen([sys.executable, "-m", "tracelab.cli", "compile", str(rules)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    snaps: list[dict] = []
    for t in range(3):  # on the counting kernel, while the child compiles
        for eng in (switching, plain):
            _drive(eng, t, None)
        _assert_same(switching, plain, t)
        if t == 1:
            snaps = [switching.snapshot(), plain.snapshot()]
    assert switching.kernel == "counting"
    assert switching.wait_for_compile(timeout=1200) == "ready"
    for t in range(3, 12):  # the first of these steps switches
        for eng, snap in zip((switching, plain), snaps):
            _drive(eng, t, snap)
        _assert_same(switching, plain, t)
        assert switching.kernel == "compiled"
    # the switched engine loaded numba's cached machine code: it compiled nothing itself
    step = switching._state.step_kernel
    assert len(step.signatures) == 1 and not step.stats.cache_misses and step.stats.cache_hits
    out, err = other.communicate(timeout=1200)
    assert other.returncode == 0, err
    job = compile_background._JOBS[entry.dir]
    compiled_here = [not job.result["cached"], "compiled and cached" in err]
    assert sorted(compiled_here) == [False, True], (job.result, err)  # exactly one of the two compiled
    assert "loaded (already cached)" in err or job.result["cached"]
    printed = caplog.text  # the engine's notices, on its logger (the CLI shows them on stderr)
    assert printed.count("being built in the background") == 1
    assert "switched to it at t=3" in printed
    assert "in the background in" in printed or "found in the cache" in printed
    # the entry holds one module, numba's files, ready.json and nothing left over (pickles, logs, temp files)
    left = sorted(p.name for p in entry.dir.iterdir())
    assert left == ["__pycache__", "compile.lock", "kernel.py", "ready.json"], left
    # the next run finds the kernel: auto takes it at once
    assert Engine(program, worlds=2).kernel == "compiled"


def test_a_failed_background_compile_leaves_the_run_on_the_counting_kernel(
        tmp_path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """The child computes another key than the run (as after a library upgrade between them): it refuses
    before compiling, and the run goes on on the counting kernel with a one-line notice."""
    monkeypatch.setenv(cc.CACHE_ENV, str(tmp_path))
    real = cc.versions()
    monkeypatch.setattr(cc, "versions", lambda: {**real, "numba": real["numba"] + ".other"})
    program = parse_program(SMALL.replace("r4: d(X) <-2", "r4: d(X) <-3"))  # a key no other test compiles
    eng = Engine(program, kernel="compiled", background_compile=True)
    assert eng.wait_for_compile(timeout=600) == "failed"
    eng.step()
    assert eng.kernel == "counting" and eng.background is None
    assert "background compile failed" in eng.kernel_notice and "asked for" in eng.kernel_notice
    notices = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(notices) == 1 and "going on with the counting kernel" in notices[0]


def test_an_unwritable_cache_leaves_the_run_on_the_counting_kernel(tmp_path, monkeypatch: pytest.MonkeyPatch,
                                                                   caplog: pytest.LogCaptureFixture) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")  # the cache root is under a file: nothing can be created there
    monkeypatch.setenv(cc.CACHE_ENV, str(blocker))
    eng = Engine(parse_program(SMALL), kernel="compiled", background_compile=True)
    eng.step()
    assert eng.kernel == "counting" and eng.background is None
    assert "cannot start its background compile" in eng.kernel_notice
    (notice,) = caplog.records
    assert notice.levelno == logging.WARNING and notice.getMessage().startswith("kernel 'compiled' not used")
