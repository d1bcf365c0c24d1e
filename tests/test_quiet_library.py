"""A quiet library (issue 28 §4): the engine prints nothing when used from Python; it logs its notices to
the `tracelab` loggers, and the CLI (tracelab/commands/_notices.py) shows them on stderr as before."""
from __future__ import annotations

import logging

import pytest
from tracelab.cli import main
from tracelab.engine import Engine, parse_program

# a quantifier: kernel="compiled" does not take it, and says so (without compiling anything)
QUANTIFIED = """
friend(x,f1)
friend(x,f2)
popular(f1)
popular(f2)
r1: liked(X) <-0 friend(X,Y), [>= 2] popular(Y)
"""


def test_the_engine_prints_nothing_when_used_from_python(capfd: pytest.CaptureFixture[str],
                                                         caplog: pytest.LogCaptureFixture) -> None:
    eng = Engine(parse_program(QUANTIFIED), kernel="compiled")
    eng.step()
    assert eng.kernel == "counting"
    assert capfd.readouterr() == ("", "")
    # the notice is on the engine's logger (and on the engine), for an application to show as it likes
    (record,) = [r for r in caplog.records if r.name.startswith("tracelab.")]
    assert record.name == "tracelab.engine.core" and record.levelno == logging.WARNING
    assert record.getMessage() == eng.kernel_notice
    assert "rule r1" in eng.kernel_notice and "counting kernel" in eng.kernel_notice


def test_the_cli_shows_the_engines_notice_on_stderr(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    rules = tmp_path / "liked.rules"
    rules.write_text(QUANTIFIED)
    assert main(["reason", str(rules), "--steps", "1", "--kernel", "compiled", "--no-trace"]) == 0
    out, err = capsys.readouterr()
    notices = [ln for ln in err.splitlines() if "kernel 'compiled'" in ln]
    assert notices == ["tracelab: notice: kernel 'compiled' not used: rule r1 (" + str(rules) + ":6:1) has a "
                       "quantifier or an annotation function; running on the counting kernel"], err
    assert "liked(x)" in out
    # the command is over: the library is quiet again in this process
    Engine(parse_program(QUANTIFIED), kernel="compiled")
    assert capsys.readouterr() == ("", "")
