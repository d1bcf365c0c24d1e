"""A first `tracelab play` on empty caches starts its games at once (issue 40): the kernels run as their
Python source (engine/numba_python.py) while a background process compiles them, and the run records
exactly the rows the compiled kernels record. Times are measured by `tracelab bench first-run`, never here."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numba.core.event as numba_event
import pytest

from test_trace_rows_unchanged import EXPECTED, GAMES, run_digests
from tracelab.cli import main
from tracelab.commands._cold_start import COLD_START, ColdStart
from tracelab.engine import kernel
from tracelab.engine.numba_python import PythonKernels, running_as_python
from tracelab.envs.declared import fused
from tracelab.first_run_figures import measured
from store_helpers import run_rows

ROOT = Path(__file__).resolve().parents[1]
SPEC = str(ROOT / "rules" / "toytext" / "frozen_lake.toml")


class _Compiles(numba_event.Listener):
    def __init__(self) -> None:
        self.names: list[str] = []

    def on_start(self, event: numba_event.Event) -> None:
        self.names.append(str(event.data["dispatcher"]))

    def on_end(self, event: numba_event.Event) -> None:
        pass


def _as_python(argv: list[str]) -> list[str]:
    """main(argv) with every loaded kernel run as Python; the numba compiles it started."""
    import tracelab.envs.declared.gym_env  # noqa: F401  (loaded before the swap, as play's cold start does)
    import tracelab.envs.declared.recording  # noqa: F401
    kernels, compiles = PythonKernels(), _Compiles()
    kernels.swap()
    numba_event.register("numba:compile", compiles)
    try:
        assert main(argv) == 0
    finally:
        numba_event.unregister("numba:compile", compiles)
        kernels.restore()
    assert not running_as_python()
    return compiles.names


@pytest.mark.parametrize("game", ["gridwar", "frozenlake"])
def test_the_kernels_run_as_python_record_the_compiled_kernels_rows(game: str, tmp_path: Path) -> None:
    run = tmp_path / "run"
    assert _as_python([*GAMES[game], "--run", str(run)]) == []  # nothing compiled
    assert run_digests(run) == EXPECTED[game]  # the digests of the compiled kernels' run


def test_a_cold_play_starts_at_once_and_compiles_in_the_background(tmp_path: Path) -> None:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "TRACELAB_CACHE_DIR": str(tmp_path / "tl")}
    env.pop(COLD_START, None)
    run = tmp_path / "run"
    child = subprocess.Popen([sys.executable, "-P", "-m", "tracelab", "play", "--env", SPEC, "--episodes", "3",
                              "--seed", "3", "--run", str(run)], env=env, cwd=tmp_path, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    lines, background = [], None
    try:
        for line in child.stderr:
            lines.append(line.rstrip("\n"))
            found = re.search(r"\(pid (\d+)\)", line)
            if found and background is None:  # a minute of CPU, measured by the bench, not here
                background = int(found.group(1))
                os.killpg(background, signal.SIGKILL)
        assert child.wait(timeout=300) == 0, lines
    finally:
        child.kill()
        child.wait(timeout=60)
        child.stderr.close()
    first = [ln for ln in lines if "first run" in ln]
    assert len(first) == 1 and first[0].startswith("tracelab: first run: the engine's kernels are not compiled "
                                                   "yet, so the games play on their Python source"), lines
    assert measured("play") in first[0]  # the figure `tracelab bench first-run` measured
    assert not [ln for ln in lines if ln.startswith("tracelab: compiling")]  # the games did not wait
    assert run_rows(run, "SELECT count(*) FROM episodes") == [(3,)]
    assert background is not None and "background compile of the kernels failed" in lines[-1]  # it was killed


def test_the_play_switches_to_the_compiled_kernels_once_the_background_compile_ended() -> None:
    assert main(["play", "--env", SPEC, "--episodes", "1", "--no-trace"]) == 0  # compiled and cached, if not yet
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait(timeout=120)
    failed = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
    failed.wait(timeout=120)
    watched = (kernel.step_worlds, fused.fused_step)  # the suite's cache holds them
    kernels = PythonKernels()
    kernels.swap()
    try:
        cold = ColdStart(kernels, failed, watched)
        cold.between_episodes(1)
        assert running_as_python() and cold.switched_after is None
        assert "failed (exit status 3)" in cold.final_line()
        cold = ColdStart(kernels, ended, watched)
        cold.between_episodes(2)
        assert not running_as_python() and cold.switched_after == 2
        assert kernel.step_worlds is watched[0]  # the dispatchers are back
    finally:
        kernels.restore()


def test_the_background_compiles_output_goes_to_a_log_that_a_failure_names(tmp_path: Path,
                                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """Its output went to /dev/null, so an error there was lost: it goes to a log in tracelab's cache folder,
    removed when the compile succeeds, named by the last line when it failed."""
    from tracelab.commands._cold_start import LOG_FOLDER, start_compile
    monkeypatch.setenv("TRACELAB_CACHE_DIR", str(tmp_path / "tl"))
    missing = tmp_path / "missing.toml"
    job, log = start_compile(["play", "--env", str(missing)])
    assert job.wait(timeout=300) != 0
    assert log is not None and log.parent == tmp_path / "tl" / LOG_FOLDER
    said = log.read_text()
    assert "tracelab: error:" in said and "missing.toml" in said, said
    line = ColdStart(PythonKernels(), job, (), log).final_line()
    assert "background compile of the kernels failed" in line and str(log) in line, line

    job, log = start_compile(["play", "--env", SPEC, "--no-trace"])  # the suite's cache holds its kernels
    assert job.wait(timeout=300) == 0
    assert log is not None and not log.exists()  # nothing to read: removed
