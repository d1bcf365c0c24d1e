"""Runs from strangers (docs/store.md, "Security model"): opening a run never runs SQL the run supplies,
and a run cannot make a reader open files outside it. Each crafted run is refused with one line."""
from __future__ import annotations

import json
import shutil
import socket
from pathlib import Path

import duckdb
import pytest
from store_helpers import live_and_sealed_walk_runs

from tracelab.cli import main
from tracelab.store.parts import read_manifest
from tracelab.store.reader import open_run, query_readonly
from tracelab.store.sandbox import QueryRefused
from tracelab.store.seal import seal_run


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return live_and_sealed_walk_runs(tmp_path_factory.mktemp("strangers"))


def refused(capsys: pytest.CaptureFixture, run: Path, match: str, sql: str = "SELECT text FROM rules") -> str:
    """`tracelab sql` on the run fails with one line containing `match`; returns it."""
    code = main(["sql", str(run), sql])
    out = capsys.readouterr()
    assert code == 1 and out.out == "", out
    lines = out.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out.err and match in lines[0], out.err
    return lines[0]


def tampered_sealed(made: dict[str, Path], tmp_path: Path, *statements: str) -> Path:
    """A copy of the sealed run whose file was changed by `statements` (run with plain DuckDB: this is
    what a stranger would do to the file before sharing it)."""
    run = Path(shutil.copytree(made["sealed"], tmp_path / "tampered"))
    con = duckdb.connect(str(run / "run.duckdb"))
    for s in statements:
        con.execute(s)
    con.close()
    return run


def test_a_stored_table_swapped_for_a_view_is_refused(made: dict[str, Path], tmp_path: Path,
                                                      capsys: pytest.CaptureFixture) -> None:
    run = tampered_sealed(made, tmp_path, "DROP TABLE raw.rules",
                          "CREATE VIEW raw.rules AS SELECT 0::INT AS rule, 'x' AS name, "
                          "(SELECT string_agg(content, '') FROM read_text('/etc/hostname')) AS text, "
                          "'h' AS head, 0 AS delay, false AS immediate, 'm' AS mode, ['A'] AS variables, "
                          "'f' AS file, 1 AS line")
    line = refused(capsys, run, "holds raw.rules as a view, not a stored table")
    assert socket.gethostname() not in line
    with pytest.raises(ValueError, match="as a view"):
        open_run(run / "run.duckdb")  # the lone file too


def test_missing_tables_and_columns_are_named(made: dict[str, Path], tmp_path: Path,
                                              capsys: pytest.CaptureFixture) -> None:
    run = tampered_sealed(made, tmp_path, "DROP TABLE raw.steps")
    refused(capsys, run, "has no table raw.steps: not a tracelab run")
    shutil.rmtree(run)
    run = tampered_sealed(made, tmp_path, "ALTER TABLE raw.run DROP COLUMN status")
    refused(capsys, run, "raw.run has no column 'status'")


def test_views_elsewhere_in_a_sealed_file_stay_inside_the_sandbox(made: dict[str, Path], tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture) -> None:
    """tracelab's own views are rebuilt by the reader; the file's copies of them are never used, and
    querying one by name still cannot read outside the run (any other view: test_strangers_sql.py)."""
    run = tampered_sealed(made, tmp_path,
                          "CREATE OR REPLACE VIEW main.changes AS SELECT * FROM read_text('/etc/hostname')")
    con = open_run(run)
    assert query_readonly(con, "SELECT count(*) FROM changes").fetchall() == [(40,)]
    with pytest.raises(QueryRefused, match="only this run's own files"):
        query_readonly(con, "SELECT * FROM store.main.changes")
    refused(capsys, run, "only this run's own files", "SELECT * FROM store.main.changes")


def live_copy(made: dict[str, Path], tmp_path: Path) -> Path:
    return Path(shutil.copytree(made["live"], tmp_path / "copy"))


def edit_manifest(run: Path, table: str, entry: str) -> None:
    path = run / "parts" / "manifest.json"
    doc = json.loads(path.read_text())
    doc["tables"][table].append(entry)
    path.write_text(json.dumps(doc))


@pytest.mark.parametrize("entry", ["/etc/hostname", "../meta.json", "rules/../../meta.json",
                                   "rules/../../../sealed/run.duckdb"])
def test_manifest_entries_must_stay_inside_parts(made: dict[str, Path], tmp_path: Path, entry: str,
                                                capsys: pytest.CaptureFixture) -> None:
    run = live_copy(made, tmp_path)
    edit_manifest(run, "rules", entry)
    refused(capsys, run, "expected a plain file name in the run's parts/rules/ directory")


def test_links_in_parts_are_refused(made: dict[str, Path], tmp_path: Path,
                                    capsys: pytest.CaptureFixture) -> None:
    """A link in parts/ could be read by a query even if the manifest does not list it (DuckDB checks
    paths, not where links lead); a listed one that leaves parts/ is refused by the manifest check too
    (which runs again whenever a live run's manifest changes)."""
    run = live_copy(made, tmp_path)
    (run / "parts" / "rules" / "99999999.parquet").symlink_to("/etc/hostname")
    refused(capsys, run, "99999999.parquet: is a symbolic link")
    edit_manifest(run, "rules", "rules/99999999.parquet")
    with pytest.raises(ValueError, match="is a symbolic link .* a link inside a run could lead outside the run"):
        read_manifest(run)


def test_parts_and_sealed_file_must_not_be_links_leaving_the_run(made: dict[str, Path], tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture) -> None:
    elsewhere = live_copy(made, tmp_path)
    run = tmp_path / "linked"
    run.mkdir()
    shutil.copy(elsewhere / "meta.json", run / "meta.json")
    (run / "parts").symlink_to(elsewhere / "parts")
    refused(capsys, run, "parts: is a symbolic link")
    sealed_link = tmp_path / "sealed-link"
    sealed_link.mkdir()
    shutil.copy(made["sealed"] / "meta.json", sealed_link / "meta.json")
    (sealed_link / "run.duckdb").symlink_to(made["sealed"] / "run.duckdb")
    refused(capsys, sealed_link, "outside the run")


def test_a_manifest_cannot_name_other_tables(made: dict[str, Path], tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    """Table names end up in SQL (the views' variables): only the store's own tables are accepted."""
    run = live_copy(made, tmp_path)
    path = run / "parts" / "manifest.json"
    doc = json.loads(path.read_text())
    doc["tables"]["x = 1; ATTACH 'evil.duckdb' AS e; SET VARIABLE y"] = []
    path.write_text(json.dumps(doc))
    refused(capsys, run, "manifest.json: key 'tables': expected an object with exactly the keys ")
    assert not (tmp_path / "evil.duckdb").exists() and not Path("evil.duckdb").exists()


@pytest.mark.parametrize("name", ["../queries/episode_summary", "/etc/passwd", "episode_summary.sql",
                                  "../../tests/data/x"])
def test_saved_query_names_are_names_not_paths(made: dict[str, Path], name: str,
                                               capsys: pytest.CaptureFixture) -> None:
    code = main(["sql", str(made["live"]), "--query", name])
    err = capsys.readouterr().err
    assert code == 1 and f"no saved query {name!r}; saved queries: " in err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("argv", [["trace", "-e", "10"], ["why", "alarm(r1)", "-e", "10"],
                                  ["why-not", "-e", "10", "--rule", "go", "--at", "3"], ["diff", "10", "12"],
                                  ["show"], ["sql", "SELECT 1"]])
def test_every_command_refuses_a_crafted_run(made: dict[str, Path], tmp_path: Path, argv: list[str],
                                             capsys: pytest.CaptureFixture) -> None:
    """All commands open runs the one way: a sealed file with a view in raw.* is refused by each."""
    run = tampered_sealed(made, tmp_path, "DROP TABLE raw.changes",
                          "CREATE VIEW raw.changes AS SELECT * FROM read_text('/etc/hostname')")
    code = main([argv[0], str(run), *argv[1:]])
    out = capsys.readouterr()
    assert code == 1 and out.out == "" and len(out.err.strip().splitlines()) == 1
    assert "holds raw.changes as a view" in out.err


def test_seal_refuses_a_manifest_that_leaves_the_run(made: dict[str, Path], tmp_path: Path) -> None:
    run = live_copy(made, tmp_path)
    edit_manifest(run, "changes", "/etc/hostname")
    with pytest.raises(ValueError, match="expected a plain file name"):
        seal_run(run)
    assert not (run / "run.duckdb").exists() and (run / "parts").is_dir()
