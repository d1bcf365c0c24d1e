"""A built wheel holds every data file tracelab reads at run time: the rule programs and specs of rules/
(mapped to tracelab/rules), the store's queries and the first-run figures. Before: a plain `pip install .`
left rules/ out, and every world, scenario and example failed to load outside the source tree."""
from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

from patience import PATIENCE

ROOT = Path(__file__).resolve().parents[1]
DATA_SUFFIXES = {".rules", ".toml", ".graphml"}


def test_the_wheel_ships_the_rules_and_the_package_data(tmp_path: Path) -> None:
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", str(ROOT),
                    "-w", str(tmp_path)], check=True, capture_output=True, timeout=PATIENCE)
    [wheel] = tmp_path.glob("tracelab-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    rules = [p for p in (ROOT / "rules").rglob("*") if p.suffix in DATA_SUFFIXES]
    assert len(rules) > 10
    missing = [str(p) for p in rules if f"tracelab/rules/{p.relative_to(ROOT / 'rules').as_posix()}" not in names]
    assert not missing, missing
    queries = [f"tracelab/queries/{p.name}" for p in (ROOT / "tracelab" / "queries").glob("*.sql")]
    assert queries and set(queries) <= names
    assert "tracelab/first_run_figures.json" in names
    assert "tracelab/engine/kernel.py" in names and "tracelab/viewers/tui/app.py" in names
