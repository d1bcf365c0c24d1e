"""SQL from strangers (issue 24, sections 3-5): a sealed run's catalog is checked before anything in it
is read, so SQL the file brings along never runs; Ctrl-C stops a long `tracelab sql` query (exit 130)
and Esc cancels one in the TUI's console; every sandbox refusal is one line."""
from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import pytest
from store_helpers import TRACELAB, ctrl_c_after_start, live_and_sealed_walk_runs, tampered_copy

from tracelab.cli import main
from tracelab.store.reader import open_run
from tracelab.store.schema import STORED_COLUMNS

ROOT = Path(__file__).resolve().parent.parent
SAMPLE_RUNS = sorted(p for p in (ROOT / "sample_runs").iterdir() if (p / "run.duckdb").is_file())
# Runs for minutes on any machine (10^12 rows), in constant memory.
ENDLESS = "SELECT sum(a.range * b.range) FROM range(1000000) a, range(1000000) b"


@pytest.fixture(scope="module")
def sealed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return live_and_sealed_walk_runs(tmp_path_factory.mktemp("strangers-sql"))["sealed"]


def one_line_error(argv: list[str], capsys: pytest.CaptureFixture) -> str:
    """`tracelab ARGV` fails with exit 1 and one line on stderr, no traceback; returns the line."""
    code = main(argv)
    out = capsys.readouterr()
    lines = out.err.strip().splitlines()
    assert code == 1 and len(lines) == 1 and "Traceback" not in out.err, out.err
    assert lines[0].startswith("tracelab: error: ")
    return lines[0]


def run_table_sql(columns: dict[str, str], changed: dict[str, str]) -> str:
    """CREATE TABLE raw.run with the expected columns, some of them declared otherwise."""
    return "CREATE TABLE raw.run (" + ", ".join(
        f'"{c}" {changed.get(c, t)}' for c, t in columns.items()) + ")"


def computed_command_copy(sealed: Path, dest: Path) -> Path:
    """A copy of the sealed run whose raw.run.command is computed on read: it succeeds where the file was
    made (external access on) and fails with 'payload ran' inside tracelab's sandbox."""
    payload = ("VARCHAR GENERATED ALWAYS AS (CASE WHEN current_setting('enable_external_access') "
               "THEN 'made' ELSE error('payload ran') END) VIRTUAL")
    return tampered_copy(sealed, dest,
                         "CREATE TABLE saved AS SELECT * EXCLUDE (command) FROM raw.run", "DROP TABLE raw.run",
                         run_table_sql(STORED_COLUMNS["run"], {"command": payload}),
                         "INSERT INTO raw.run BY NAME SELECT * FROM saved", "DROP TABLE saved")


# ---- section 3: the sealed file's catalog ---------------------------------------------------------------

def test_a_generated_column_is_refused_before_its_expression_runs(sealed: Path, tmp_path: Path) -> None:
    """raw.run.command computed on read: it succeeds where the file was made (external access on) and
    fails with 'payload ran' inside tracelab's sandbox, so any read of it would show that text."""
    run = computed_command_copy(sealed, tmp_path / "generated")
    for command in (["show", str(run)], ["sql", str(run), "SELECT command FROM run"]):
        done = subprocess.run([*TRACELAB, *command], capture_output=True, text=True, timeout=120)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 1 and len(lines) == 1, done.stderr
        assert "payload ran" not in done.stderr + done.stdout
        assert "raw.run.command is a generated column" in lines[0] and str(run / "run.duckdb") in lines[0]


@pytest.mark.parametrize("statements, named", [
    (["ALTER TABLE raw.steps ALTER COLUMN reward SET DEFAULT random()"], "raw.steps.reward has a default"),
    (["CREATE MACRO main.evil(x) AS x || (SELECT content FROM read_text('/etc/hostname'))"],
     "holds a macro main.evil"),
    (["CREATE MACRO raw.every_change() AS TABLE SELECT * FROM raw.changes"], "holds a macro raw.every_change"),
    (["CREATE VIEW main.evil AS SELECT repeat('A', 2000000000) AS a"], "holds a view main.evil"),
    (["CREATE TABLE main.extra AS SELECT 1 AS x"], "holds a table main.extra"),
    (["CREATE TABLE raw.extra AS SELECT 1 AS x"], "holds a table raw.extra"),
    (["CREATE SCHEMA evil"], "holds a schema evil"),
    (["CREATE SCHEMA s", "CREATE SCHEMA s.raw"], "holds a schema s.raw"),  # a second raw, nested
    (["CREATE SEQUENCE main.counter"], "holds a sequence main.counter"),
    (["CREATE INDEX by_reward ON raw.steps ((reward + 1))"], "holds an index raw.by_reward"),
    (["CREATE TRIGGER wipe AFTER INSERT ON raw.nodes FOR EACH STATEMENT DELETE FROM raw.steps"],
     "holds a trigger raw.wipe"),
    (["ALTER TABLE raw.steps ALTER COLUMN reward SET NOT NULL"], "holds a constraint raw.steps NOT NULL"),
    (["CREATE TYPE main.mood AS ENUM ('happy')"], "holds a type main.mood"),
])
def test_anything_seal_does_not_write_is_refused_by_name(sealed: Path, tmp_path: Path, statements: list[str],
                                                         named: str, capsys: pytest.CaptureFixture) -> None:
    run = tampered_copy(sealed, tmp_path / "tampered", *statements)
    line = one_line_error(["sql", str(run), "SELECT count(*) FROM changes"], capsys)
    assert named in line and str(run / "run.duckdb") in line, line


def test_columns_are_the_expected_ones_and_older_runs_still_open(sealed: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture) -> None:
    for i, (statement, named) in enumerate([
            ("ALTER TABLE raw.steps ALTER COLUMN reward TYPE VARCHAR", "raw.steps.reward is VARCHAR, not DOUBLE"),
            ("ALTER TABLE raw.run ADD COLUMN extra INTEGER", "raw.run has a column extra"),
            ("ALTER TABLE raw.steps DROP COLUMN obs", "raw.steps has no column 'obs'")]):
        run = tampered_copy(sealed, tmp_path / str(i), statement)
        assert named in one_line_error(["sql", str(run), "SELECT count(*) FROM steps"], capsys)
    # a run sealed before clauses.closed existed reads it as false
    older = tampered_copy(sealed, tmp_path / "older", "ALTER TABLE raw.clauses DROP COLUMN closed")
    assert open_run(older).execute("SELECT DISTINCT closed FROM raw.clauses").fetchall() == [(False,)]
    for run in SAMPLE_RUNS:  # sealed before clauses.closed too; they open, and stay as they are
        before = (run / "run.duckdb").read_bytes()
        con = open_run(run)
        assert con.execute("SELECT count(*) FROM changes").fetchone()[0] > 0
        assert con.execute("SELECT status FROM run").fetchone()[0] == "finished"
        con.close()
        assert (run / "run.duckdb").read_bytes() == before


def test_a_write_ahead_log_beside_the_sealed_file_is_not_replayed(sealed: Path, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture) -> None:
    """DuckDB replays a .wal on ATTACH, running the SQL in it (here an ALTER ... USING expression)."""
    run = tampered_copy(sealed, tmp_path / "wal", "PRAGMA disable_checkpoint_on_shutdown",
                        "SET wal_autocheckpoint = '1TB'",
                        "ALTER TABLE raw.run ALTER COLUMN command TYPE VARCHAR USING 'the log ran this'")
    assert (run / "run.duckdb.wal").is_file()
    line = one_line_error(["sql", str(run), "SELECT command FROM run"], capsys)
    assert "run.duckdb.wal" in line and "write-ahead log" in line and "the log ran" not in line


# ---- section 4: stopping a long query -------------------------------------------------------------------

@pytest.mark.parametrize("query", [ENDLESS, "EXPLAIN ANALYZE " + ENDLESS], ids=["select", "explain-analyze"])
@pytest.mark.parametrize("fmt", ["table", "csv"])
def test_ctrl_c_stops_a_long_sql_query(query: str, fmt: str) -> None:
    """Before: the query ran on (30 s and more), or DuckDB's own check ended it as an error (exit 1);
    EXPLAIN ANALYZE, interrupted, was run again."""
    status, lines, cpu = ctrl_c_after_start(["sql", str(SAMPLE_RUNS[0]), query, "--format", fmt])
    assert cpu < 3
    assert status == 130 and len(lines) == 1 and lines[0].startswith("tracelab: interrupted"), lines


def test_escape_cancels_a_running_query_in_the_tui_console() -> None:
    from tracelab.viewers.tui.lazy_table import LazyTable
    from tracelab.viewers.tui.sql import SqlPane
    from tui_helpers import episodes_ready, loaded, run_app, wait_for

    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("5")
        await wait_for(pilot, lambda: app.screen.panes["sql"].is_attached)
        sql: SqlPane = app.screen.panes["sql"]
        status = sql.query_one("#sql-status")
        sql.editor.text = ENDLESS
        await pilot.press("ctrl+r")
        await wait_for(pilot, lambda: app.screen.source.busy)
        await pilot.press("escape")
        await wait_for(pilot, lambda: "cancelled" in str(status.render()))
        assert sql.last_error is None and str(sql.query_one("#sql-error").render()) == ""
        assert type(app.screen).__name__ == "RunScreen"          # Esc cancelled; it did not go back
        sql.editor.text = "SELECT * FROM sniff_csv('/etc/passwd')"  # a refusal: one friendly line
        await pilot.press("ctrl+r")
        await wait_for(pilot, lambda: sql.last_error is not None)
        assert sql.last_error.message.startswith("a query may read only this run's own files")
        assert "\n" not in sql.last_error.message
        sql.editor.text = "SELECT count(*) AS n FROM episodes"   # the connection still works
        await pilot.press("ctrl+r")
        results = sql.query_one(LazyTable)
        await wait_for(pilot, lambda: loaded(results) and results.count == 1)
        assert results.row(0)["n"] == 3
    run_app([ROOT / "sample_runs" / "advanced"], body)


# ---- section 5: every refusal is one line ---------------------------------------------------------------

OUTSIDE = ["SELECT * FROM sniff_csv('/etc/passwd')", "SELECT * FROM duckdb_secrets()",
           "SELECT * FROM duckdb_extensions()", "SELECT * FROM which_secret('s3://bucket/key', 's3')",
           "SELECT * FROM read_text('/etc/passwd')", "SELECT * FROM read_blob('/etc/passwd')",
           "SELECT * FROM glob('/etc/*')", "SELECT * FROM read_csv_auto('/etc/passwd')",
           "SELECT * FROM parquet_scan('/etc/passwd')", "SELECT * FROM parquet_metadata('/etc/passwd')",
           "SELECT * FROM read_json_auto('/etc/passwd')", "SELECT * FROM 'http://example.com/x.csv'"]


@pytest.mark.parametrize("fmt", ["table", "json"])
def test_queries_reaching_outside_the_run_are_refused_in_one_line(fmt: str, capsys: pytest.CaptureFixture) -> None:
    """Before: sniff_csv, duckdb_secrets, duckdb_extensions and which_secret ended in a traceback
    (QueryRefused was raised outside the command's error handling)."""
    for query in OUTSIDE:
        line = one_line_error(["sql", str(SAMPLE_RUNS[0]), query, "--format", fmt], capsys)
        assert "a query may read only this run's own files" in line, (query, line)
        assert "root:" not in line  # nothing of /etc/passwd


HARMLESS = ["SELECT * FROM duckdb_settings()", "SELECT * FROM pragma_database_size()",
            "SELECT * FROM pragma_table_info('raw.run')", "SELECT * FROM checkpoint()",
            "SELECT * FROM force_checkpoint()", "SELECT * FROM query('COPY (SELECT 1) TO ''x.csv''')",
            "SELECT * FROM test_all_types()", "SELECT 'infinity'::TIMESTAMP AS t"]


def test_system_functions_are_harmless_and_never_a_traceback(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture) -> None:
    """Before: values Python's datetime cannot hold (test_all_types(), 'infinity') ended in a traceback."""
    monkeypatch.chdir(tmp_path)
    for query in HARMLESS:
        for fmt in ("table", "csv"):
            code = main(["sql", str(SAMPLE_RUNS[0]), query, "--format", fmt])
            err = capsys.readouterr().err
            assert code in (0, 1) and "Traceback" not in err and len(err.strip().splitlines()) <= 1, (query, err)
    assert list(tmp_path.iterdir()) == []  # wrote nothing
