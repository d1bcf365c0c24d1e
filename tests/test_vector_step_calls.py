"""The batch's compiled step (vector_fused.step_worlds) calls the counting kernel's step itself, as the one
world's (fused.fused_step) does: kernel.fused_step, a wrapper that only set the step's t, compiled a copy of
the whole linked kernel into it (~3 s of CPU on a fresh cache, docs/benchmarks.md, "Issue 40: the start of
eval and train"). Run as Python (engine/numba_python.py: the same source, no compile) to see the calls."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracelab.engine import kernel
from tracelab.engine.numba_python import PythonKernels
from tracelab.envs.declared.vector_env import DeclaredVectorEnv

SPEC = str(Path(__file__).resolve().parents[1] / "rules" / "toytext" / "frozen_lake.toml")


def test_the_batch_step_calls_the_kernels_step_not_the_fused_wrapper(monkeypatch: pytest.MonkeyPatch) -> None:
    env = DeclaredVectorEnv(SPEC, 2, kernel="counting")
    kernels = PythonKernels()
    kernels.swap()
    calls: list[str] = []
    try:
        run = kernel.step_worlds

        def counted(*args):  # noqa: ANN001, ANN002, ANN202
            calls.append("step_worlds")
            return run(*args)
        monkeypatch.setattr(kernel, "step_worlds", counted)
        env.reset(seed=1)
        for _ in range(3):
            env.step(np.array([1, 2]))
    finally:
        monkeypatch.undo()
        kernels.restore()
        env.close()
    assert calls.count("step_worlds") == 3, calls
    assert not hasattr(kernel, "fused_step")   # the wrapper compiled a second copy of the kernel (~3 s)
