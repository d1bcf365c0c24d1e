"""`tracelab bench pyreason` (docs/pyreason.md, "Switching from PyReason"): tracelab's side on PyReason's
hello world, each run a fresh process, with the report's fields; PyReason itself is not installed here,
so its side is skipped with one line, and a --pyreason-python without PyReason is a one-line error.
Nothing here asserts a speed: the figures come from the bench on a real PyReason install."""
from __future__ import annotations

import importlib.util
import json
import re
import sys
from pathlib import Path

import pytest

from tracelab.bench import pyreason_compare
from tracelab.cli import main


def test_tracelab_side_on_the_hello_world(capsys: pytest.CaptureFixture) -> None:
    # --timeout bounds each run's process: a regression fails instead of hanging
    assert main(["bench", "pyreason", "--quick", "--json", "--timeout", "900"]) == 0
    out, err = capsys.readouterr()
    notice = [line for line in err.splitlines() if "--pyreason-python" in line]
    assert notice == ["tracelab: bench pyreason: PyReason's side not run (give --pyreason-python PYTHON, the "
                      "interpreter of a PyReason install)"]
    r = json.loads(out)
    # each run, as it ends, is one JSON line on stderr: a stopped bench keeps what it measured
    ended = [json.loads(line.split(": ", 1)[1]) for line in err.splitlines() if line.startswith("bench pyreason run: ")]
    assert [(e["program"], e["side"], e["kind"]) for e in ended] == [("hello world", "tracelab", "first run"),
                                                                   ("hello world", "tracelab", "warm")]
    assert r["pyreason"] is None and r["warm_repeats"] == 1
    assert list(r["programs"]) == ["hello world"]
    hello = r["programs"]["hello world"]
    assert hello["script"] == "examples/pyreason_hello_world.py" and "pyreason" not in hello
    side = hello["tracelab"]
    assert side["first_cold"] is True and ended[0]["cpu_s"] == side["first"]["cpu_s"]
    for run in (side["first"], *side["warm"]):
        assert run["error"] is None
        # the script's own last line: Justin is popular at t = 2, as in PyReason's documented output
        assert run["result"].split() == ["2", "Justin", "[1.0,", "1.0]"]
        assert run["wall_s"] > 0 and run["cpu_s"] > 0 and run["peak_rss_bytes"] > 50 * 2**20
        # memory over time: (seconds, bytes) samples, in time order, none above the peak
        times = [t for t, _ in run["rss_samples"]]
        assert times and times == sorted(times)
        assert max(rss for _, rss in run["rss_samples"]) <= run["peak_rss_bytes"]
        assert len(run["load_before"]) == 3
    assert len(side["warm"]) == 1 and side["warm_cpu_s"]["median"] == side["warm"][0]["cpu_s"]
    text = pyreason_compare.report(r)
    assert "PyReason not run (no --pyreason-python)" in text
    assert re.search(r"^hello world, tracelab, first run: .*\(\d+s\) \d+$", text, re.M), text  # its time and MB


def test_a_pyreason_python_that_is_missing_or_has_no_pyreason_is_one_line(capsys: pytest.CaptureFixture,
                                                                           tmp_path: Path) -> None:
    missing = tmp_path / "no-python"
    assert main(["bench", "pyreason", "--pyreason-python", str(missing)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == f"tracelab: error: --pyreason-python {missing}: no such file"
    assert "Traceback" not in "\n".join(err)
    if importlib.util.find_spec("pyreason") is None:  # this interpreter has no PyReason
        assert main(["bench", "pyreason", "--pyreason-python", sys.executable]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1] == (f"tracelab: error: --pyreason-python {sys.executable}: PyReason is not installed "
                           f"there (`{sys.executable} -m pip install pyreason`)")
