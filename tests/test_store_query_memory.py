"""The query sandbox bounds memory (docs/store.md, "Security model"): every connection that reads a run has a
memory limit (a quarter of the machine, at most 4 GiB, or $TRACELAB_QUERY_MEMORY), threads and spill files
to match, all in force before the first query and locked; a query over the limit is one line naming the
limit and how to raise it, and a big sort spills to a private folder instead of failing."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import duckdb
import pytest
from store_helpers import live_and_sealed_walk_runs

from tracelab.cli import main
from tracelab.store.reader import open_run, query_readonly
from tracelab.store.sandbox import QueryRefused, query_memory
from tracelab.store.several import open_runs

TRACELAB = Path(sys.executable).parent / "tracelab"
MIB = 1 << 20
# a query whose one result string outgrows 64 MiB (an aggregate DuckDB cannot spill)
TOO_BIG = "SELECT length(string_agg(range::VARCHAR, ',')) FROM range(30000000)"
# a sort of ~130 MB of strings: over a 100 MiB limit, so it must spill to finish
BIG_SORT = "SELECT b FROM (SELECT range::VARCHAR || repeat('x', 30) AS b FROM range(3000000)) ORDER BY b DESC " \
           "OFFSET 2999999"


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return live_and_sealed_walk_runs(tmp_path_factory.mktemp("memory"))


def settings(con: duckdb.DuckDBPyConnection) -> tuple[str, int, str]:
    return con.execute("SELECT current_setting('memory_limit'), current_setting('threads'), "
                       "current_setting('max_temp_directory_size')").fetchall()[0]


@pytest.mark.parametrize("kind", ["live", "sealed", "several"])
def test_the_limits_are_in_force_and_locked(runs: dict[str, Path], kind: str) -> None:
    limits = query_memory()
    assert limits.memory <= 4 << 30 and limits.spill <= 4 * limits.memory  # not DuckDB's 80% of the machine
    con = open_runs([runs["live"], runs["sealed"]]) if kind == "several" else open_run(runs[kind])
    memory, threads, spill = settings(con)
    assert memory == f"{limits.memory / (1 << 30):.1f} GiB"
    assert threads == limits.threads <= max(1, limits.memory >> 30)
    assert spill == f"{limits.spill / (1 << 30):.1f} GiB"
    with pytest.raises(QueryRefused, match="only read-only queries"):
        query_readonly(con, "SET memory_limit = '100GB'")
    for statement in ("SET memory_limit = '100GB'", "SET threads = 64", "SET max_temp_directory_size = '1TB'",
                      "RESET memory_limit", "PRAGMA memory_limit = '100GB'"):
        with pytest.raises(duckdb.Error, match="locked"):
            con.execute(statement)
    assert settings(con)[0] == memory


def test_the_environment_sets_the_limit(runs: dict[str, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TRACELAB_QUERY_MEMORY", "300M")
    con = open_run(runs["sealed"])
    assert settings(con)[:2] == ("300.0 MiB", 1)


def test_a_query_over_the_limit_is_one_line_naming_it(runs: dict[str, Path], capsys: pytest.CaptureFixture,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TRACELAB_QUERY_MEMORY", "64M")
    assert main(["sql", str(runs["live"]), TOO_BIG]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("tracelab: error: out of memory (")
    assert "may use 64 MiB of memory (set by TRACELAB_QUERY_MEMORY)" in err
    assert "set TRACELAB_QUERY_MEMORY to raise both (e.g. TRACELAB_QUERY_MEMORY=1G)" in err
    assert "SET memory_limit" not in err  # DuckDB's advice, which the sandbox refuses


def test_over_the_limit_in_a_separate_process(runs: dict[str, Path], tmp_path: Path) -> None:
    env = {**os.environ, "TRACELAB_QUERY_MEMORY": "64M"}
    proc = subprocess.run([str(TRACELAB), "sql", str(runs["sealed"]), TOO_BIG], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1 and proc.stdout == "", proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "TRACELAB_QUERY_MEMORY" in proc.stderr, proc.stderr


def test_a_bad_limit_is_one_line(runs: dict[str, Path], capsys: pytest.CaptureFixture,
                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TRACELAB_QUERY_MEMORY", "lots")
    assert main(["sql", str(runs["sealed"]), "SELECT 1"]) == 1
    assert capsys.readouterr().err == ("tracelab: error: TRACELAB_QUERY_MEMORY='lots': expected a size such as "
                                       "8G or 500M, got 'lots'\n")


def test_a_big_sort_spills_within_the_limit_and_leaves_nothing(runs: dict[str, Path],
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TRACELAB_QUERY_MEMORY", "100M")
    con = open_run(runs["sealed"])
    assert settings(con)[0] == "100.0 MiB"
    ((spill,),) = con.execute("SELECT current_setting('temp_directory')").fetchall()
    assert query_readonly(con, BIG_SORT).fetchall() == [("0" + "x" * 30,)]
    assert os.listdir(spill)  # DuckDB's spill file, in the folder of this connection
    assert (os.stat(Path(spill).parent).st_mode & 0o077) == 0  # a private folder: no one else reads it
    con.close()
    assert not os.path.exists(spill)
