"""The query sandbox (docs/store.md, "Security model"): `tracelab sql` and everything else that opens a run
can read the run's own files and nothing else, writes nothing, never reaches the network, never loads an
extension. Every attack is refused with one line; the run's files hash the same afterwards; nothing
appears under the home directory or the working directory."""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from store_helpers import live_and_sealed_walk_runs, write_walk_run

from tracelab.cli import main
from tracelab.store.reader import open_run, query_readonly
from tracelab.store.sandbox import QueryRefused

TRACELAB = Path(sys.executable).parent / "tracelab"


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A live run (Parquet parts), a sealed run, and another run whose files must stay out of reach."""
    base = tmp_path_factory.mktemp("sandbox")
    return {**live_and_sealed_walk_runs(base), "other": write_walk_run(base / "other")}


def attacks(run: Path, other: Path, scratch: Path) -> list[str]:
    """Statements that would read outside the run, write, reach the network or load code."""
    own_file = next(run.glob("parts/changes/*.parquet"), run / "run.duckdb")
    return [
        f"EXPLAIN ANALYZE COPY (SELECT 1) TO '{own_file}'",
        f"EXPLAIN ANALYZE COPY (SELECT 1) TO '{scratch}/copied.csv'",
        "EXPLAIN ANALYZE CREATE TABLE x AS SELECT 1",
        "explain /* hidden */ analyze (format json) create table x as select 1",
        "SELECT * FROM read_csv('/etc/passwd')",
        "SELECT * FROM read_text('/etc/hostname')",
        "SELECT * FROM glob('/etc/*')",
        "SELECT * FROM read_csv('http://127.0.0.1:9/x.csv')",
        "SELECT * FROM read_parquet('https://example.com/x.parquet')",
        f"SELECT * FROM read_parquet('{other}/parts/changes/00000000.parquet')",
        f"SELECT * FROM read_parquet('{run}/parts/../../other/parts/changes/00000000.parquet')",
        f"ATTACH '{scratch}/attached.duckdb' AS x",
        "INSTALL httpfs",
        "LOAD httpfs",
        "SET enable_external_access = true",
        "RESET enable_external_access",
        "PRAGMA enable_profiling",
        f"COPY changes TO '{scratch}/changes.csv'",
        f"COPY (SELECT 1) TO '{own_file}'",
        "CREATE TABLE x AS SELECT 1",
        "SELECT 1; COPY changes TO 'x.csv'",
    ]


def fingerprint(root: Path) -> dict[str, str]:
    """sha256 of every file under root, by relative path."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("kind", ["live", "sealed"])
def test_every_attack_is_refused_in_one_line(runs: dict[str, Path], kind: str, tmp_path: Path,
                                              capsys: pytest.CaptureFixture,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    run = runs[kind]
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(tmp_path)
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    before, other_before = fingerprint(run), fingerprint(runs["other"])
    for statement in attacks(run, runs["other"], scratch):
        code = main(["sql", str(run), statement])
        err = capsys.readouterr().err
        assert code == 1, statement
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, (statement, err)
        assert "root:" not in err, statement
    assert fingerprint(run) == before
    assert fingerprint(runs["other"]) == other_before
    assert list(home.iterdir()) == [] and list(scratch.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["home", "scratch"]


def test_the_cli_refuses_attacks_in_a_separate_process_with_its_own_home(runs: dict[str, Path],
                                                                         tmp_path: Path) -> None:
    run = runs["sealed"]
    home = tmp_path / "home"
    home.mkdir()
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    before = fingerprint(run)
    env = {**os.environ, "HOME": str(home)}
    for statement in attacks(run, runs["other"], scratch)[:12]:
        proc = subprocess.run([str(TRACELAB), "sql", str(run), statement], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=60)
        assert proc.returncode == 1, (statement, proc.stderr)
        assert len(proc.stderr.strip().splitlines()) == 1, (statement, proc.stderr)
        assert "Traceback" not in proc.stderr and proc.stdout == ""
    assert fingerprint(run) == before
    assert list(home.iterdir()) == [] and list(scratch.iterdir()) == []


@pytest.mark.parametrize("kind", ["live", "sealed"])
def test_queries_still_read_the_run(runs: dict[str, Path], kind: str) -> None:
    con = open_run(runs[kind])
    assert query_readonly(con, "SELECT count(*) FROM changes").fetchall() == [(40,)]
    plan = query_readonly(con, "EXPLAIN ANALYZE SELECT count(*) FROM firings").fetchall()
    assert "firings" in str(plan).lower() or plan
    assert query_readonly(con, "DESCRIBE episodes").fetchall()
    assert query_readonly(con, "SUMMARIZE SELECT * FROM steps").fetchall()
    # the connection's own settings cannot be changed back, not even from Python
    for statement in ("SET enable_external_access = true", "SET allowed_directories = ['/']",
                      "SET autoload_known_extensions = true"):
        with pytest.raises(Exception, match="locked"):
            con.execute(statement)


def test_statement_check_looks_inside_explain(runs: dict[str, Path]) -> None:
    con = open_run(runs["sealed"])
    for statement in ("EXPLAIN COPY changes TO 'x'", "EXPLAIN (ANALYZE) DELETE FROM raw.changes",
                      "EXPLAIN ANALYZE INSERT INTO x VALUES (1)"):
        with pytest.raises(QueryRefused, match="EXPLAIN runs or plans"):
            query_readonly(con, statement)
    with pytest.raises(QueryRefused, match="one SQL statement, got 2"):
        query_readonly(con, "SELECT 1; SELECT 2")
    with pytest.raises(QueryRefused, match="name the values: PIVOT"):
        query_readonly(con, "PIVOT episodes ON outcome USING count(*)")
    assert query_readonly(con, "PIVOT episodes ON outcome IN ('win', 'loss') USING count(*)").fetchall()


def test_reading_the_runs_own_parts_is_allowed_and_nothing_else(runs: dict[str, Path]) -> None:
    live = runs["live"]
    con = open_run(live)
    part = sorted(live.glob("parts/changes/*.parquet"))[-1]
    assert query_readonly(con, f"SELECT count(*) FROM read_parquet('{part}')").fetchall()[0][0] > 0
    with pytest.raises(QueryRefused, match="only this run's own files"):
        query_readonly(con, f"SELECT * FROM read_text('{live}/meta.json')")


def test_a_copied_run_reads_the_same(runs: dict[str, Path], tmp_path: Path) -> None:
    """Runs are shared by copying their directory: the sandbox follows the run, not where it was made."""
    copy = shutil.copytree(runs["live"], tmp_path / "copy")
    assert open_run(copy).execute("SELECT count(*) FROM changes").fetchall() == [(40,)]
