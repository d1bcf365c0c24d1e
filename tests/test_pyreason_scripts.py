"""PyReason scripts run unchanged (issue 41): `python -m tracelab.pyreason SCRIPT.py ARGS` and `tracelab
run-pyreason` resolve `import pyreason`, `from pyreason import ...` and `from pyreason.scripts... import`
to tracelab's modules in that process only. The scripts are real files run in a new process."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("networkx")
pytest.importorskip("pandas")

# three import styles in one script, PyReason's threshold example's program (examples/custom_threshold_ex.py)
SCRIPT = '''
import sys
import pyreason as pr
from pyreason import Threshold
from pyreason.scripts.rules.rule import Rule
from pyreason.scripts.facts.fact import Fact
import networkx as nx

g = nx.DiGraph()
for who in ["Zach", "Justin", "Michelle", "Amy"]:
    g.add_edge(who, "TextMessage", HaveAccess=1)
pr.load_graph(g)
pr.add_rule(Rule("ViewedByAll(y) <- HaveAccess(x,y), Viewed(x)", "viewed_by_all_rule",
                 custom_thresholds=[Threshold("greater_equal", ("number", "total"), 1),
                                    Threshold("greater_equal", ("percent", "total"), 100)]))
for who, start in [("Zach", 0), ("Justin", 0), ("Michelle", 1), ("Amy", 2)]:
    pr.add_fact(Fact(f"Viewed({who})", f"seen-{who}", start, 3))
interpretation = pr.reason(timesteps=int(sys.argv[1]))
for t, df in enumerate(pr.filter_and_sort_nodes(interpretation, ["ViewedByAll"])):
    print(t, df["component"].tolist())
print("pyreason is", pr.__name__)
'''


def run(tmp_path: Path, *command: str) -> subprocess.CompletedProcess:
    script = tmp_path / "threshold_example.py"
    script.write_text(SCRIPT)
    return subprocess.run([sys.executable, *command, str(script), "3"], capture_output=True, text=True,
                          timeout=600, check=False, cwd=tmp_path)


def test_a_pyreason_script_runs_unchanged_with_python_m(tmp_path: Path) -> None:
    r = run(tmp_path, "-m", "tracelab.pyreason")
    assert r.returncode == 0, r.stderr
    # PyReason's documented answer: TextMessage is viewed by all from t = 2, once Amy has viewed it
    assert r.stdout.splitlines() == ["0 []", "1 []", "2 ['TextMessage']", "3 ['TextMessage']",
                                     "pyreason is tracelab.pyreason"]


def test_run_pyreason_command_and_nothing_installed_as_pyreason(tmp_path: Path) -> None:
    r = run(tmp_path, "-m", "tracelab", "run-pyreason")
    assert r.returncode == 0, r.stderr
    assert "2 ['TextMessage']" in r.stdout
    # outside such a run the name stays free: nothing was installed under it
    probe = subprocess.run([sys.executable, "-c", "import importlib.util as u; print(u.find_spec('pyreason'))"],
                           capture_output=True, text=True, timeout=120, check=True)
    assert probe.stdout.strip() == "None"


def test_a_pyreason_module_tracelab_lacks_and_a_missing_script_are_one_line(tmp_path: Path) -> None:
    script = tmp_path / "yolo.py"
    script.write_text("from pyreason.scripts.learning.classification.yolo_classifier import X\n")
    r = subprocess.run([sys.executable, "-m", "tracelab.pyreason", str(script)], capture_output=True, text=True,
                       timeout=300, check=False)
    assert r.returncode == 1
    assert r.stderr.strip().splitlines()[-1].endswith(
        "tracelab.pyreason has no module standing for PyReason's "
        "pyreason.scripts.learning.classification.yolo_classifier"
        " (docs/pyreason.md, 'Scripts as they are')")
    r = subprocess.run([sys.executable, "-m", "tracelab.pyreason", str(tmp_path / "none.py")], capture_output=True,
                       text=True, timeout=300, check=False)
    assert (r.returncode, r.stderr.strip()) == (1, f"tracelab: error: {tmp_path / 'none.py'}: No such file")
