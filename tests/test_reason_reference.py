"""`tracelab reason` on a small program answers from the reference evaluator without loading numba (issue 40),
printing what the compiled engine prints (`--kernel counting` forces the engine: the same command, the
other evaluator); a program it cannot finish, and one too big for it, run on the compiled engine; `--json`
says which ran."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tracelab.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "rules" / "examples"

CHILD = """
import contextlib, io, sys
from tracelab.cli import main
with contextlib.redirect_stdout(io.StringIO()) as out:
    status = main(sys.argv[1:])
print(status, 'numba' in sys.modules, 'final interpretation' in out.getvalue())
"""


def reasoned(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str, str]:
    status = main(["reason", *argv])
    out = capsys.readouterr()
    return status, out.out, out.err


@pytest.mark.parametrize("program", ["reach", "popular", "supply_chain_fix"])
def test_a_small_program_prints_what_the_compiled_engine_prints(program: str,
                                                                capsys: pytest.CaptureFixture) -> None:
    rules = str(EXAMPLES / f"{program}.rules")
    by_reference = reasoned(capsys, rules, "--steps", "6")
    compiled = reasoned(capsys, rules, "--steps", "6", "--kernel", "counting")
    assert by_reference == compiled and by_reference[0] == 0 and "final interpretation at t=5:" in compiled[1]
    doc, engine_doc = (json.loads(reasoned(capsys, rules, "--steps", "6", "--json", *kernel)[1])
                       for kernel in ([], ["--kernel", "counting"]))
    assert doc["stats"]["evaluator"] == "reference" and engine_doc["stats"]["evaluator"] == "compiled"
    assert doc["changes"] == engine_doc["changes"] and doc["interpretation"] == engine_doc["interpretation"]
    assert doc["stats"]["changes"] == engine_doc["stats"]["changes"] == len(doc["changes"]) > 0


def test_reach_rules_answer_without_numba() -> None:
    out = subprocess.run([sys.executable, "-c", CHILD, "reason", str(EXAMPLES / "reach.rules"), "--steps", "5"],
                         capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert out.stdout.split() == ["0", "False", "True"], out.stderr


def test_what_the_reference_cannot_finish_runs_compiled(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    rules = tmp_path / "clash.rules"
    rules.write_text("%inconsistency abort\np(a)\nr1: q(X) <-0 p(X)\nr2: q(X):[0,0] <-0 p(X)\n")
    status, out, err = reasoned(capsys, str(rules), "--steps", "2")
    assert status == 1 and out == ""
    assert err.startswith("tracelab: error: inconsistent bounds for q(a) at t=0 (world 0): rule r1 (")  # the engine's


def test_a_big_program_runs_compiled(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """400 nodes and two variables: 160,000 assignments a pass, beyond the reference evaluator's share."""
    rules = tmp_path / "chain.rules"
    rules.write_text("".join(f"edge(n{i}, n{i + 1}) static\n" for i in range(400)) +
                     "reach(n0)\nspread: reach(Y) <-1 reach(X), edge(X, Y)\n")
    status, out, _ = reasoned(capsys, str(rules), "--steps", "3", "--json")
    doc = json.loads(out)
    assert status == 0 and doc["stats"]["evaluator"] == "compiled" and doc["interpretation"]["reach(n2)"] == [1, 1]
