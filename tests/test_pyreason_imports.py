"""What PyReason's hello world (examples/pyreason_hello_world.py) imports, run as a user runs it in a new
process: nothing it does not use. Each module kept out here cost the warm hello world CPU time it does not
need (docs/benchmarks/history.md, "PyReason's API"): scipy.linalg (numba's BLAS check, engine/numba_startup.py),
the lanes kernel (a single world runs on the counting kernel), the compiled GraphML scanner (a small file is
read by expat), and the heavy parts of tracelab a reasoning without `settings.tracelab_run` never touches.
Not a timing test: a module that comes back fails it on any machine."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("pandas")

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "pyreason_hello_world.py"

# the script's run, then what it imported and what numba says of BLAS afterwards
PROBE = """
import json, runpy, sys
runpy.run_path(sys.argv[1], run_name="__main__")
loaded = sorted(sys.modules)
import numba.np.arraymath
from tracelab.engine import memory
print(json.dumps({"modules": loaded, "blas": bool(numba.np.arraymath._HAVE_BLAS),
                  "scipy_blas_after": "scipy.linalg.cython_blas" in sys.modules,
                  "malloc_trim_looked_up": memory._malloc_trim.cache_info().misses
                                           if hasattr(memory, "_malloc_trim") else None}))
"""

NOT_IMPORTED = ("scipy.linalg", "tracelab.engine.lanes", "tracelab.engine.backend_lanes",
                "tracelab.engine.graphml_scan", "torch", "duckdb", "tracelab.store", "gymnasium", "textual",
                "networkx", "rerun", "tracelab.commands")


@pytest.fixture(scope="module")
def probe() -> dict:
    out = subprocess.run([sys.executable, "-c", PROBE, str(EXAMPLE)], capture_output=True, text=True,
                         timeout=600, check=True)
    lines = out.stdout.strip().splitlines()
    assert lines[0] == "TIMESTEP - 0", out.stdout  # the script itself ran and printed its DataFrames
    return json.loads(lines[-1])


def test_the_hello_world_imports_only_what_it_uses(probe: dict) -> None:
    loaded = set(probe["modules"])
    assert {"pandas", "numba", "tracelab.engine.kernel"} <= loaded  # the probe saw the reasoning's imports
    heavy = sorted(m for m in loaded for name in NOT_IMPORTED if m == name or m.startswith(name + "."))
    assert heavy == []
    assert probe["malloc_trim_looked_up"] == 0  # a small graph: no `ldconfig -p` subprocess for libc


def test_numba_still_answers_blas_as_its_own_check_does(probe: dict) -> None:
    """scipy.linalg held back at numba's start-up changes no answer: asked afterwards, numba's BLAS flag is
    what its own import-time check gives (scipy is imported then, by the code that asks)."""
    pytest.importorskip("scipy.linalg")
    assert probe["blas"] is True
    assert probe["scipy_blas_after"] is True


def test_the_modules_imported_with_it_are_left_out_of_garbage_collection(tmp_path: Path) -> None:
    """`import tracelab.pyreason` freezes the objects alive then (numba's, ~0.25 s of CPU at exit), and
    nothing made after it: a script's reference cycle holding an unclosed file is still collected at
    exit, so the file is flushed as without tracelab."""
    out_file = tmp_path / "written.txt"
    code = ("import gc, sys, tracelab.pyreason\n"
            "print(gc.get_freeze_count())\n"
            "class Holder: pass\n"
            "h = Holder(); h.me = h; h.f = open(sys.argv[1], 'w'); h.f.write('kept')\n")
    out = subprocess.run([sys.executable, "-c", code, str(out_file)], capture_output=True, text=True,
                         timeout=300, check=True)
    assert int(out.stdout) > 10_000
    assert out_file.read_text() == "kept"
