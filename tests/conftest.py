"""Run with pytest-xdist (the README's `python -m pytest -q -n 2 --dist loadfile`), the two workers would
both start on a cold numba cache (CI's) and compile the engine's and a declared world's kernels at the
same moment: twice the CPU for the same machine code, and numba rewrites a function's cache index without
a lock, so two processes saving different signatures of one function at once could pair an entry with
the other's machine code. So before the workers start, one process fills the cache: `tracelab.bench.probe`
(what `tracelab bench engine` runs to fill it) builds the game's engine and GridWar's spec (war.toml) and
steps each once.
A few seconds when the cache is warm; a plain `pytest` (no -n) does not run it."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

WARM_UP_TIMEOUT = 1800  # seconds: a cold compile takes one or two minutes of CPU on a loaded machine


def pytest_configure(config: pytest.Config) -> None:
    # a play on a cold cache compiles in this process, as the suite's other tests do: its default, Python
    # kernels and a background compile (tracelab/commands/_cold_start.py), would compile the same kernels
    # in a second process at the same time (the cache race above); tests/test_first_run_python.py tests it
    os.environ.setdefault("TRACELAB_COLD_START", "wait")
    is_controller = not hasattr(config, "workerinput")
    if is_controller and getattr(config.option, "numprocesses", None):
        # the result is not checked: if the engine is broken, the tests say how, not a traceback here
        subprocess.run([sys.executable, "-m", "tracelab.bench.probe", "game", "spec"], capture_output=True,
                       timeout=WARM_UP_TIMEOUT, check=False)
