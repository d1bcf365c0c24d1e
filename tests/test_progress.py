"""tracelab/commands/_progress.py: quiet off a terminal, a bar on one, and the cold-cache check that
decides when to say "compiling the engine"."""
from __future__ import annotations

import os
import pty
import select
import subprocess
import sys
from pathlib import Path

from tracelab.commands._progress import engine_cache_is_cold, progress


def test_off_a_terminal_progress_only_counts(capsys) -> None:
    with progress("playing", total=10, unit="episodes") as bar:
        bar.advance(3)
        bar.set_fields(wins=2)
    assert bar.completed == 3 and bar.figures == {"wins": 2}
    assert capsys.readouterr() == ("", "")


def _cold_in_a_fresh_process(cache_dir: str | None) -> str:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    if cache_dir:
        env["NUMBA_CACHE_DIR"] = cache_dir
    code = "from tracelab.commands._progress import engine_cache_is_cold as c; print(c(), c(local_trace=True))"
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=False,
                          timeout=300).stdout.strip()


def test_the_cold_cache_check_reads_numbas_index(tmp_path: Path) -> None:
    # an empty cache directory: nothing compiled yet, the first run will compile
    assert _cold_in_a_fresh_process(str(tmp_path)) == "True True"
    # in this process, once the engine has stepped its kernel is loaded: nothing to compile
    from tracelab.engine import Engine, parse_program
    Engine(parse_program("p(a)\nq(X) <-0 p(X)")).step()
    assert engine_cache_is_cold() is False


def run_on_a_terminal(args: list[str], columns: int = 150) -> tuple[int, str]:
    """`python -m tracelab ARGS` with stdout and stderr on a pseudo-terminal: (exit status, what it drew)."""
    master, slave = pty.openpty()
    p = subprocess.Popen([sys.executable, "-m", "tracelab", *args], stdin=slave, stdout=slave, stderr=slave,
                         env={**os.environ, "COLUMNS": str(columns)})
    os.close(slave)
    chunks = []
    while True:
        ready, _, _ = select.select([master], [], [], 300)
        if not ready:
            break
        try:
            data = os.read(master, 65536)
        except OSError:  # the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    p.wait(timeout=300)
    os.close(master)
    return p.returncode, b"".join(chunks).decode(errors="replace")


def test_on_a_terminal_play_draws_a_bar_and_reports_its_rate() -> None:
    code, text = run_on_a_terminal(["play", "--scenario", "base", "--episodes", "4", "--no-trace"])
    assert code == 0, text
    assert "playing base" in text and "episodes/s" in text and "eta" in text
    assert "played 4 episodes of base (" in text and " steps/s)" in text  # its world built before the clock


def test_watch_grounding_reports_the_groundings_found_so_far() -> None:
    from tracelab.engine import Engine, parse_program
    from tracelab.engine.grounding import watch_grounding
    seen: list[int] = []
    with watch_grounding(seen.append):
        eng = Engine(parse_program("edge(a,b)\nedge(b,c)\nedge(c,d)\nreach(a)\n"
                                   "spread: reach(Y) <-1 reach(X), edge(X,Y)"))
        eng.run(4)
    eng.run(1)  # outside: nobody is told
    assert seen and seen == sorted(seen) and seen[-1] == len(eng.groundings.rule)
