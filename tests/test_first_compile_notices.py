"""Every first compile a user meets says so in one line, with what `tracelab bench first-run` measured
(issue 40): a declared world's env and vector env (the library logs it, the CLI shows it), play's and
reason's (the CLI's own notice). The cold cases read the line, then stop the process: the compile itself
is not waited for (minutes of CPU here); the bench measures it."""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tracelab import first_run_figures
from tracelab.first_run_figures import measured, say_first_compile

ROOT = Path(__file__).resolve().parents[1]
SPEC = str(ROOT / "rules" / "toytext" / "frozen_lake.toml")
VECTOR = ("import logging; logging.basicConfig(level=logging.INFO, format='%(message)s'); "
          f"from tracelab.envs import make_vec_env; make_vec_env({SPEC!r}, 8)")


def _first_notice(argv: list[str], cache: Path) -> str:
    """The first stderr line that says `compiling` of a process on empty caches; the process is stopped
    there (or its whole stderr when it ends without one)."""
    # play compiles first (its default on empty caches plays at once: tests/test_first_run_python.py)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache / "numba"), "TRACELAB_CACHE_DIR": str(cache / "tracelab"),
           "TRACELAB_COLD_START": "wait"}
    child = subprocess.Popen(argv, env=env, cwd=cache, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    seen = []
    try:
        for line in child.stderr:
            seen.append(line)
            if "compiling" in line:
                return line.rstrip("\n")
        child.wait(timeout=300)
        return "".join(seen)
    finally:
        child.kill()
        child.wait(timeout=60)
        child.stderr.close()


def test_a_declared_worlds_first_compile_is_said_on_the_command_line(tmp_path: Path) -> None:
    line = _first_notice([sys.executable, "-P", "-m", "tracelab", "play", "--env", SPEC, "--episodes", "1"], tmp_path)
    assert line.startswith("tracelab: compiling the rule engine's step kernel and a declared world's step for "), line
    assert SPEC in line and "(first run only" in line


def test_a_declared_vector_envs_first_compile_is_logged_by_the_library(tmp_path: Path) -> None:
    line = _first_notice([sys.executable, "-P", "-c", VECTOR], tmp_path)
    assert line.startswith("compiling the rule engine's step kernel and a declared world's batch step for "), line


def test_a_notice_is_said_once_per_process_and_only_when_something_compiles(caplog: pytest.LogCaptureFixture,
                                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(first_run_figures, "_said", set())
    log = logging.getLogger("tracelab.test")
    with caplog.at_level(logging.INFO, logger="tracelab"):
        say_first_compile(log, "spec-env", "the kernels", [True, None])  # all cached (or unknown): nothing
        say_first_compile(log, "spec-env", "the kernels", [True, False])
        say_first_compile(log, "spec-env", "the kernels", [False])  # the vector env's worlds: once
    assert [r.getMessage() for r in caplog.records] == [f"compiling the kernels ({measured('spec-env')})"]


def test_the_figure_quoted_is_the_bench_table_s(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    table = tmp_path / "figures.json"
    table.write_text(json.dumps({"measured": "2026-11-28 21:50 UTC", "load": [[0.4, 0.2, 0.1], [1.0, 0.5, 0.2]],
                                 "cores": 2, "figures": {"play": {"wall_s": 17.4, "cpu_s": 24.6}}}))
    monkeypatch.setattr(first_run_figures, "FIGURES", table)
    first_run_figures._table.cache_clear()
    try:
        assert measured("play") == ("first run only; a fresh install measured 25 s of CPU, 17 s wall at load 0 "
                                    "on 2 cores, 2026-11-28")
        assert measured("train") == "first run only"  # not measured: no figure is made up
    finally:
        first_run_figures._table.cache_clear()
