"""What PyReason's hello world (examples/pyreason_hello_world.py) imports, run as a user runs it in a new
process: nothing it does not use. Each module kept out here cost the warm hello world CPU time it does not
need (docs/benchmarks/history.md, "PyReason's API"; docs/benchmarks.md, "PyReason's warm hello world"):
numba and the engine's kernels (a program this small reasons on the reference evaluator), pandas until a
DataFrame is made, scipy.linalg (numba's BLAS check, engine/numba_startup.py, when the compiled engine
runs), the lanes kernel (a single world runs on the counting kernel), the compiled GraphML scanner (a
small file is read by expat), and the heavy parts of tracelab a reasoning without
`settings.tracelab_run` never touches. Not a timing test: a module that comes back fails it on any machine."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("pandas")

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "pyreason_hello_world.py"

# the script's run (on the evaluator argv[2] names), then what it imported and what numba says of BLAS
PROBE = """
import json, runpy, sys
import tracelab.pyreason as pr
pr.settings.tracelab_evaluator = sys.argv[2]
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
COMPILED = ("numba", "llvmlite", "scipy", "tracelab.engine.core", "tracelab.engine.kernel")


def run_probe(evaluator: str) -> dict:
    out = subprocess.run([sys.executable, "-c", PROBE, str(EXAMPLE), evaluator], capture_output=True, text=True,
                         timeout=600, check=True)
    lines = out.stdout.strip().splitlines()
    assert lines[0] == "TIMESTEP - 0", out.stdout  # the script itself ran and printed its DataFrames
    return json.loads(lines[-1])


@pytest.fixture(scope="module")
def probe() -> dict:
    return run_probe("auto")


@pytest.fixture(scope="module")
def compiled_probe() -> dict:
    return run_probe("compiled")


def loaded_of(loaded: set[str], names: tuple[str, ...]) -> list[str]:
    return sorted(m for m in loaded for name in names if m == name or m.startswith(name + "."))


def test_the_hello_world_imports_only_what_it_uses(probe: dict) -> None:
    loaded = set(probe["modules"])
    assert {"pandas", "tracelab.engine.reference"} <= loaded  # the probe saw the reasoning's imports
    assert loaded_of(loaded, NOT_IMPORTED + COMPILED) == []
    assert probe["malloc_trim_looked_up"] == 0  # a small graph: no `ldconfig -p` subprocess for libc


def test_on_the_compiled_engine_it_imports_only_what_that_uses(compiled_probe: dict) -> None:
    loaded = set(compiled_probe["modules"])
    assert {"pandas", "numba", "tracelab.engine.kernel"} <= loaded
    assert "tracelab.engine.reference" not in loaded
    assert loaded_of(loaded, NOT_IMPORTED) == []
    assert compiled_probe["malloc_trim_looked_up"] == 0


def test_numba_still_answers_blas_as_its_own_check_does(compiled_probe: dict) -> None:
    """scipy.linalg held back at numba's start-up changes no answer: asked afterwards, numba's BLAS flag is
    what its own import-time check gives (scipy is imported then, by the code that asks)."""
    pytest.importorskip("scipy.linalg")
    assert compiled_probe["blas"] is True
    assert compiled_probe["scipy_blas_after"] is True


def test_import_tracelab_pyreason_loads_neither_numba_nor_pandas() -> None:
    """`import tracelab.pyreason` (and a reasoning on the reference evaluator) loads no numba; pandas comes
    with the first DataFrame, not before (0.5 s of CPU for a script that makes none)."""
    code = ("import json, sys, networkx as nx, tracelab.pyreason as pr\n"
            "heavy = ('numba', 'llvmlite', 'pandas', 'scipy', 'tracelab.engine.kernel')\n"
            "seen = lambda: [m for m in heavy if m in sys.modules]\n"
            "steps = {'import': seen()}\n"
            "g = nx.DiGraph(); g.add_edge('a', 'b')\n"
            "pr.load_graph(g)\n"
            "pr.add_rule(pr.Rule('q(x) <-1 p(x)', 'r'))\n"
            "pr.add_fact(pr.Fact('p(a)', 'f', 0, 1))\n"
            "i = pr.reason(timesteps=2)\n"
            "steps['reason'] = seen()\n"
            "steps['query'] = [i.query(pr.Query('q(a) : [1, 1]')), seen()]\n"
            "pr.get_rule_trace(i)\n"
            "steps['rule trace'] = seen()\n"
            "print(json.dumps(steps))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert json.loads(out.stdout) == {"import": [], "reason": [], "query": [True, []], "rule trace": ["pandas"]}


def test_the_cause_kinds_read_without_numba_are_the_kernels() -> None:
    """engine/cause_kinds.py spells out the numbers kernel.py and lanes.py keep for themselves (numba
    freezes them into its cached code): the trace rows mean what tracelab.pyreason reads them as."""
    from tracelab.engine import cause_kinds, kernel, lanes
    names = [n for n in vars(cause_kinds) if n.startswith("CAUSE_")]
    assert len(names) == 5
    for n in names:
        assert getattr(kernel, n) == getattr(lanes, n) == getattr(cause_kinds, n), n


def test_the_modules_imported_with_it_are_left_out_of_garbage_collection(tmp_path: Path) -> None:
    """`import tracelab.pyreason` freezes the objects alive then (numpy's and its own; the compiled engine's
    and pandas' are frozen when they are loaded: numba's cost ~0.25 s of CPU at exit), and
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
