"""SQL across runs (issue 30, section 3): `tracelab sql RUN RUN ... "SELECT run, ..."` and folders of runs
read every run through the one sandbox, each view with a first column `run`; saved queries run on each
run; live and sealed runs mix; a run's Parquet parts read with pyarrow alone give the same rows.
The runs are real ones made by the CLI (`tracelab play`), two of them sharing the folder name seed-1."""
from __future__ import annotations

import csv
import io
import json
import re
import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.dataset as ds
import pytest
from store_helpers import ctrl_c_after_start
from test_store_sandbox import attacks, fingerprint

from tracelab.cli import main

ROOT = Path(__file__).resolve().parent.parent
REASONING_RUN = ROOT / "sample_runs" / "supply-chain"
ENDLESS = "SELECT sum(a.range * b.range) FROM range(1000000) a, range(1000000) b"


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """runs/a/seed-1 and runs/b/seed-1 (live, Parquet parts; different seeds), and a sealed copy of the
    first as sealed/seed-1."""
    base = tmp_path_factory.mktemp("several")
    made = {}
    for key, seed in (("a", 1), ("b", 2)):
        run = base / "runs" / key / "seed-1"
        assert main(["play", "--scenario", "base", "--episodes", "2", "--seed", str(seed), "--run", str(run)]) == 0
        made[key] = run
    made["sealed"] = Path(shutil.copytree(made["a"], base / "sealed" / "seed-1"))
    assert main(["seal", str(made["sealed"])]) == 0
    return made


def sql_csv(capsys: pytest.CaptureFixture, *argv: str) -> list[dict[str, str]]:
    code = main(["sql", *argv, "--format", "csv"])
    out = capsys.readouterr()
    assert code == 0, out.err
    return list(csv.DictReader(io.StringIO(out.out)))


def header(capsys: pytest.CaptureFixture, *argv: str) -> list[str]:
    """The columns of a query's result (its CSV header, there even with no rows)."""
    code = main(["sql", *argv, "--format", "csv", "--limit", "0"])
    out = capsys.readouterr()
    assert code == 0, out.err
    return next(csv.reader(io.StringIO(out.out)))


def one_line_error(capsys: pytest.CaptureFixture, *argv: str) -> str:
    code = main(["sql", *argv])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def count(capsys: pytest.CaptureFixture, run: Path, table: str) -> int:
    return int(sql_csv(capsys, str(run), f"SELECT count(*) AS n FROM {table}")[0]["n"])


def test_several_runs_read_as_one_with_a_run_column(runs: dict[str, Path], capsys: pytest.CaptureFixture) -> None:
    """Before: sql took one run (a second one was an unexpected argument)."""
    rows = sql_csv(capsys, str(runs["a"]), str(runs["b"]),
                   "SELECT run, count(*) AS n FROM changes GROUP BY run ORDER BY run")
    # the two runs share the folder name seed-1: the folder above tells them apart
    assert rows == [{"run": "a/seed-1", "n": str(count(capsys, runs["a"], "changes"))},
                    {"run": "b/seed-1", "n": str(count(capsys, runs["b"], "changes"))}]
    for view in ("changes", "firings", "episodes", "steps", "metrics", "rules", "facts", "atoms", "groundings",
                 "edges", "run", "raw.changes", "raw.run"):
        assert header(capsys, str(runs["a"]), str(runs["b"]), f"SELECT * FROM {view}")[0] == "run", view
    # one run reads as before: no run column
    assert "run" not in header(capsys, str(runs["a"]), "SELECT * FROM episodes")
    # a join within each run, across runs
    rows = sql_csv(capsys, str(runs["a"]), str(runs["b"]),
                   "SELECT e.run, e.episode, e.outcome, count(s.step) AS steps FROM episodes e "
                   "JOIN steps s ON s.run = e.run AND s.episode = e.episode GROUP BY ALL ORDER BY ALL")
    assert [r["run"] for r in rows] == ["a/seed-1"] * 2 + ["b/seed-1"] * 2


def test_a_folder_of_runs_and_a_mix_of_live_and_sealed(runs: dict[str, Path], capsys: pytest.CaptureFixture) -> None:
    folder = runs["a"].parent.parent          # runs/: holds a/ and b/, folders of runs
    rows = sql_csv(capsys, str(folder / "a"), str(folder / "b"), "SELECT DISTINCT run FROM episodes ORDER BY run")
    assert [r["run"] for r in rows] == ["a/seed-1", "b/seed-1"]
    # one folder holding one run still reads as several runs (a script over a folder sees `run` always)
    assert sql_csv(capsys, str(folder / "a"), "SELECT DISTINCT run FROM run") == [{"run": "seed-1"}]
    # the sealed copy of a and live b: the same counts as each alone
    rows = sql_csv(capsys, str(runs["sealed"]), str(runs["b"]), str(runs["a"]),
                   "SELECT run, (SELECT count(*) FROM firings f WHERE f.run = r.run) AS n, status "
                   "FROM run r ORDER BY run")
    assert rows == [{"run": "a/seed-1", "n": str(count(capsys, runs["a"], "firings")), "status": "finished"},
                    {"run": "b/seed-1", "n": str(count(capsys, runs["b"], "firings")), "status": "finished"},
                    {"run": "sealed/seed-1", "n": str(count(capsys, runs["a"], "firings")), "status": "finished"}]


def test_saved_queries_run_on_each_run(runs: dict[str, Path], capsys: pytest.CaptureFixture) -> None:
    """A saved query written for one run gives, on several, each run's rows after the run's name."""
    both = sql_csv(capsys, str(runs["a"]), str(runs["sealed"]), "--query", "episode_summary")
    alone = [sql_csv(capsys, str(r), "--query", "episode_summary") for r in (runs["a"], runs["sealed"])]
    assert both == [{"run": name, **row} for name, rows in zip(("a/seed-1", "sealed/seed-1"), alone)
                    for row in rows]
    assert len(both) == 4
    limited = sql_csv(capsys, str(runs["a"]), str(runs["b"]), "--query", "firings_per_episode", "-p", "episode=1",
                      "--offset", "1", "--limit", "3")
    full = sql_csv(capsys, str(runs["a"]), str(runs["b"]), "--query", "firings_per_episode", "-p", "episode=1")
    assert limited == full[1:4] and {r["episode"] for r in full} == {"1"}
    # a query about games names the run that is not a run of games
    line = one_line_error(capsys, str(runs["a"]), str(REASONING_RUN), "--query", "actions_per_win")
    assert str(REASONING_RUN) in line and "not a run of games" in line


def test_errors_name_the_offending_run(runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    line = one_line_error(capsys, str(runs["a"]), str(tmp_path / "gone"), "SELECT 1")
    assert "gone" in line and line.startswith("tracelab: error: no run")
    newer = Path(shutil.copytree(runs["b"], tmp_path / "newer"))
    meta = json.loads((newer / "meta.json").read_text())
    (newer / "meta.json").write_text(json.dumps({**meta, "format": "tracelab-run/2"}))
    line = one_line_error(capsys, str(runs["a"]), str(newer), "SELECT count(*) FROM changes")
    assert f"{newer}/meta.json" in line and "tracelab-run/2" in line
    (newer / "meta.json").write_text(json.dumps(meta))
    manifest = json.loads((newer / "parts" / "manifest.json").read_text())
    (newer / "parts" / "manifest.json").write_text(json.dumps({**manifest, "format": "tracelab-parts/2"}))
    line = one_line_error(capsys, str(runs["a"]), str(newer), "SELECT 1")
    assert f"{newer}/parts/manifest.json" in line and "tracelab-parts/2" in line


def test_too_many_runs_are_refused_before_any_is_opened(runs: dict[str, Path], tmp_path: Path,
                                                         capsys: pytest.CaptureFixture) -> None:
    """A folder of thousands of runs would take minutes and gigabytes: refused at once, in one line."""
    from tracelab.store.several import MAX_RUNS
    for i in range(MAX_RUNS + 1):
        (tmp_path / f"r{i:04d}").mkdir()
        shutil.copy(runs["a"] / "meta.json", tmp_path / f"r{i:04d}" / "meta.json")
    line = one_line_error(capsys, str(tmp_path), "SELECT 1")
    assert f"{MAX_RUNS + 1} runs given" in line and f"at most {MAX_RUNS}" in line and "Parquet parts" in line


def test_the_sandbox_holds_for_every_run(runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """The attacks one run refuses, refused on a live and a sealed run read together; another run's parts
    stay out of reach, the listed runs' own parts are readable."""
    home, scratch = tmp_path / "home", tmp_path / "scratch"
    home.mkdir()
    scratch.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(tmp_path)
    listed = [runs["sealed"], runs["b"]]
    before = {r: fingerprint(r) for r in runs.values()}
    for statement in attacks(runs["b"], runs["a"], scratch):
        line = one_line_error(capsys, *map(str, listed), statement)
        assert "root:" not in line, statement
    assert {r: fingerprint(r) for r in runs.values()} == before
    assert list(home.iterdir()) == [] and list(scratch.iterdir()) == []
    own = max(runs["b"].glob("parts/changes/*.parquet"), key=lambda p: p.stat().st_size)
    rows = sql_csv(capsys, *map(str, listed), f"SELECT count(*) > 0 AS ok FROM read_parquet('{own}')")
    assert rows == [{"ok": "True"}]


def test_ctrl_c_stops_a_query_on_several_runs(runs: dict[str, Path]) -> None:
    status, lines, cpu = ctrl_c_after_start(["sql", str(runs["a"]), str(runs["sealed"]), ENDLESS])
    assert cpu < 3
    assert status == 130 and len(lines) == 1 and lines[0].startswith("tracelab: interrupted"), lines


def test_a_run_sealed_while_read_is_read_from_its_sealed_file(runs: dict[str, Path], tmp_path: Path) -> None:
    from tracelab.store.reader import query_readonly
    from tracelab.store.several import open_runs
    live = Path(shutil.copytree(runs["a"], tmp_path / "live"))
    con = open_runs([live, runs["b"]])
    sql = "SELECT run, count(*) FROM changes GROUP BY run ORDER BY run"
    before = query_readonly(con, sql).fetchall()
    assert main(["seal", str(live)]) == 0 and not (live / "parts").exists()
    assert query_readonly(con, sql).fetchall() == before


# ---- the Parquet parts: a documented format any engine reads ----------------------------------------------

def documented_tables() -> dict[str, list[tuple[str, str]]]:
    """docs/store.md's table of the Parquet parts: table -> [(column, Arrow type)]."""
    text = (ROOT / "docs" / "store.md").read_text()
    section = text.split("## The Parquet parts: a format for any engine", 1)[1].split("\n## ", 1)[0]
    out = {}
    for table, columns in re.findall(r"^\| `(\w+)` \| (.+) \|$", section, re.M):
        out[table] = [tuple(c.split(": ", 1)) for c in re.findall(r"`([^`]+)`", columns)]
    return out


def test_the_documented_format_is_the_one_written() -> None:
    from tracelab.store.meta import FORMAT
    from tracelab.store.parts import MANIFEST_FORMAT
    from tracelab.store.schema import SCHEMAS
    documented = documented_tables()
    assert documented == {t: [(f.name, str(f.type)) for f in s] for t, s in SCHEMAS.items()}
    text = (ROOT / "docs" / "store.md").read_text()
    assert f"`{MANIFEST_FORMAT}`" in text and f"`{FORMAT}`" in text


def test_pyarrow_alone_reads_the_parts_as_tracelab_sql_does(runs: dict[str, Path],
                                                          capsys: pytest.CaptureFixture) -> None:
    """What docs/store.md tells another engine: read parts/manifest.json, read the files it lists (each
    table's folder), take the run's name from the path. No tracelab code below but the CLI's answer."""
    base = runs["a"].parent.parent      # runs/a/seed-1, runs/b/seed-1
    for table in ("changes", "steps", "episode_end", "atoms", "metrics"):
        files = []
        for run in (runs["a"], runs["b"]):
            manifest = json.loads((run / "parts" / "manifest.json").read_text())
            assert manifest["format"] == "tracelab-parts/1"
            files += [str(run / "parts" / entry) for entry in manifest["tables"][table]]
        # runs/<folder>/<run>/parts/<table>/<part>: the run's name is the path below `base`
        partitioning = ds.DirectoryPartitioning(pa.schema([("folder", pa.string()), ("name", pa.string())]))
        data = ds.dataset(files, format="parquet", partitioning=partitioning, partition_base_dir=str(base))
        counts = data.to_table(columns=["folder", "name"]).group_by(["folder", "name"]).aggregate([([], "count_all")])
        by_run = {f"{f}/{n}": c for f, n, c in zip(*(counts.column(i).to_pylist() for i in range(3)))}
        rows = sql_csv(capsys, str(runs["a"]), str(runs["b"]),
                       f"SELECT run, count(*) AS n FROM raw.{table} GROUP BY run")
        assert by_run == {r["run"]: int(r["n"]) for r in rows}, table
        assert data.schema.field(0).name == next(iter(documented_tables()[table]))[0]


def test_a_strangers_run_in_the_list_is_refused_before_anything_of_it_runs(
        runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Each run of the list gets the checks one run gets: a sealed file whose raw.run.command is computed
    on read (it would show 'payload ran'), and a live run whose parts/ holds a link out of it."""
    from test_strangers_sql import computed_command_copy
    tampered = computed_command_copy(runs["sealed"], tmp_path / "generated")
    line = one_line_error(capsys, str(runs["b"]), str(tampered), "SELECT run, command FROM run")
    assert f"{tampered}/run.duckdb" in line and "generated column" in line and "payload ran" not in line
    linked = Path(shutil.copytree(runs["b"], tmp_path / "linked"))
    (linked / "parts" / "changes" / "outside.parquet").symlink_to("/etc/passwd")
    line = one_line_error(capsys, str(runs["a"]), str(linked), "SELECT count(*) FROM changes")
    assert "outside.parquet" in line and "symbolic link" in line
