"""The store's CLI commands (trace, why, why-not, sql, diff, seal) through `tracelab.cli.main`."""
from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from store_helpers import write_walk_run

from tracelab.cli import main


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(write_walk_run(tmp_path_factory.mktemp("cmd") / "walk"))


def csv_rows(text: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(text)))


def cli(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_trace_prints_the_method_table(run: str, capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "trace", run, "--episode", "10", "--from", "2", "--to", "3")
    assert code == 0
    lines = out.splitlines()
    assert lines[0].split() == ["t", "node/edge", "label", "old", "new", "rule"]
    assert lines[2].split() == ["2", "(r1,a)", "at", "[1,1]", "[0,0]", "leave"]
    assert lines[3].split() == ["2", "(r1,b)", "at", "[0,1]", "[1,1]", "go"]
    assert ["3", "r1", "move", "[1,1]", "[0,0]", "action"] in [ln.split() for ln in lines]
    assert lines[-1] == "(8 rows)"


def test_trace_filters_formats_and_paging(run: str, capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    code, out, _ = cli(capsys, "trace", run, "-e", "12", "--atom", "at(r1,*)", "--format", "json")
    rows = json.loads(out)
    assert code == 0 and {r["atom"] for r in rows} == {"at(r1,a)", "at(r1,b)", "at(r1,c)", "at(r1,d)"}
    assert rows[0] == {**rows[0], "t": 0, "rule": rows[0]["rule"], "new_lower": 1.0}
    assert rows[0]["rule"].startswith("fact:")
    _, out, _ = cli(capsys, "trace", run, "-e", "12", "--rule", "go", "--rule", "action", "--format", "csv")
    assert out.splitlines()[0].startswith("t,pass_no,atom,node,label,old_lower")
    assert {r["rule"] for r in csv_rows(out)} == {"go", "action"}
    _, out, _ = cli(capsys, "trace", run, "-e", "12", "--label", "near", "--limit", "2", "--offset", "1",
                    "--format", "csv")
    assert [r["atom"] for r in csv_rows(out)] == ["near(r1,c)", "near(r1,d)"]
    target = tmp_path / "t.parquet"
    assert cli(capsys, "trace", run, "-e", "10", "--format", "parquet", "-o", str(target))[0] == 0
    table = pq.read_table(target)
    assert table.num_rows == 16 and table.column("rule").to_pylist()[-1] == "near"


def test_trace_of_a_missing_episode_names_the_known_ones(run: str, capsys: pytest.CaptureFixture) -> None:
    code, _, err = cli(capsys, "trace", run, "-e", "5")
    assert code == 1
    assert err.strip() == f"tracelab: error: episode 5 has no trace rows in {run} (episodes with rows: [10, 11, 12])"
    code, _, err = cli(capsys, "trace", "no-such-run", "-e", "5")
    assert code == 1 and "no run 'no-such-run'" in err


def test_why_and_why_not_commands(run: str, capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "why", run, "alarm(r1)", "--episode", "10", "--at", "4")
    assert code == 0 and out.startswith("alarm(r1) = [1,1] at the end of t=4: set at t=3 pass 1")
    code, out, _ = cli(capsys, "why", run, "at(r1,d)", "-e", "12", "--depth", "1", "--json")
    doc = json.loads(out)
    assert code == 0 and doc["at"] == 5 and doc["tree"]["cause"]["name"] == "go"  # --at defaults to the end
    code, out, _ = cli(capsys, "why-not", run, "-e", "10", "--rule", "go", "--grounding", "A=r1", "--at", "4")
    assert code == 0 and out.splitlines()[-1] == "first failed clause: #3 move(r1):[1,1] (move(r1) = [0,0])"
    code, out, _ = cli(capsys, "why-not", run, "-e", "10", "--rule", "go", "--grounding", "A=r1,X=c",
                       "--at", "4", "--json")
    assert code == 0 and json.loads(out)["failed"] == 2
    code, _, err = cli(capsys, "why-not", run, "-e", "10", "--rule", "go", "--grounding", "A", "--at", "4")
    assert code == 1 and "cannot read binding 'A'" in err
    code, _, err = cli(capsys, "why", run, "at(r1,zz)", "-e", "10")
    assert code == 1 and err.strip() == "tracelab: error: no node 'zz' in this run; its nodes: a, b, c, d, r1"


ADVANCED = str(Path(__file__).resolve().parents[1] / "sample_runs" / "advanced")


def test_why_pass_explains_one_of_several_changes_in_a_step(capsys: pytest.CaptureFixture) -> None:
    """acting(clock) changes twice at t=1 of the advanced sample run: cleared by clr_acting in pass 0, set
    again by p_act in pass 1 (immediate). Without --pass why explains the end of the step and says so."""
    code, out, err = cli(capsys, "why", ADVANCED, "acting(clock)", "-e", "0", "--at", "1", "--depth", "1")
    assert code == 0
    assert out.startswith("acting(clock) = [1,1] at the end of t=1: set at t=1 pass 1 [0,0]->[1,1] by p_act")
    assert "changed 2 times at t=1 (passes 0, 1)" in err and "--pass 0" in err
    code, out, err = cli(capsys, "why", ADVANCED, "acting(clock)", "-e", "0", "--at", "1", "--pass", "0", "--json")
    doc = json.loads(out)
    assert code == 0 and doc["pass"] == 0 and doc["tree"]["cause"]["name"] == "clr_acting" and not err
    code, out, _ = cli(capsys, "why", ADVANCED, "acting(clock)", "-e", "0", "--at", "1", "--pass", "0")
    assert out.startswith("acting(clock) = [0,0]: set at t=1 pass 0 [1,1]->[0,0] by clr_acting")
    code, _, err = cli(capsys, "why", ADVANCED, "acting(clock)", "-e", "0", "--at", "1", "--pass", "3")
    assert code == 1 and err.strip() == ("tracelab: error: acting(clock) did not change in pass 3 of t=1; it "
                                         "changed then in passes 0, 1")
    code, _, err = cli(capsys, "why", ADVANCED, "alive(red-agent-1)", "-e", "0", "--at", "1", "--pass", "0")
    assert code == 1 and "alive(red-agent-1) did not change at t=1" in err


def test_sql_is_read_only_and_shows_error_positions(run: str, capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "sql", run, "SELECT episode, count(*) AS n FROM changes GROUP BY 1 ORDER BY 1",
                       "--format", "csv")
    assert code == 0 and out.splitlines() == ["episode,n", "10,16", "11,7", "12,17"]
    code, _, err = cli(capsys, "sql", run, "SELECT nope FROM changes")
    assert code == 1 and err.count("\n") == 1 and "nope" in err and "(at line 1, column 8 of the query)" in err
    for statement in ("DROP VIEW changes", "CREATE TABLE x AS SELECT 1", "COPY changes TO 'x.csv'",
                      f"ATTACH '{run}/x.duckdb' AS x", "SELECT 1; SELECT 2"):
        code, _, err = cli(capsys, "sql", run, statement)
        assert code == 1 and ("read-only" in err or "one SQL statement" in err), statement
    assert not Path("x.csv").exists()
    code, out, _ = cli(capsys, "sql", run, "SELECT * FROM range(10) r(i) ORDER BY i", "--limit", "3",
                       "--offset", "2", "--format", "csv")
    assert out.split() == ["i", "2", "3", "4"]


def test_sql_saved_queries(run: str, capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "sql", run, "--list")
    assert code == 0 and "firings_per_episode:" in out and "    episode (int, default None)" in out
    code, out, _ = cli(capsys, "sql", run, "--query", "firings_per_episode", "--param", "episode=10",
                       "--format", "csv")
    assert code == 0 and out.splitlines() == ["episode,rule,firings,first_t,last_t", "10,near,3,0,3",
                                               "10,go,2,2,3", "10,leave,2,2,3", "10,alarm,1,3,3"]
    code, _, err = cli(capsys, "sql", run, "--query", "firings_per_episode", "--param", "colour=1")
    assert code == 1 and "no parameter(s) ['colour']" in err
    code, _, err = cli(capsys, "sql", run, "--query", "firings_per_episode", "--param", "episode=ten")
    assert code == 1 and "parameter episode must be int, got 'ten'" in err
    code, _, err = cli(capsys, "sql", run, "--query", "nothing")
    assert code == 1 and "no saved query 'nothing'" in err


def test_diff_finds_the_first_divergence(run: str, capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "diff", run, "10", "12")
    assert code == 0
    assert "first different action: step 3 agent r1: 0 in 10, 1 in 12" in out
    assert "first divergence of the trace: 3 steps in (t=3 in episode 10, t=3 in episode 12)" in out
    code, out, _ = cli(capsys, "diff", run, "10", "12", "--json")
    d = json.loads(out)
    assert d["rel_t"] == 3 and not d["identical"]
    # at t=3 episode 10 stops (its action) while 12 keeps going: that is all that differs at t=3
    assert [(r["atom"], r["rule"], r["new_lower"]) for r in d["only_in_a"]] == [("move(r1)", "action", 0.0)]
    assert d["only_in_b"] == []
    code, out, _ = cli(capsys, "diff", run, "11", "12", "--json")
    d = json.loads(out)
    assert d["rel_t"] == 1 and d["only_in_a"] == [] and [r["atom"] for r in d["only_in_b"]] == ["move(r1)"]
    assert d["first_action_difference"] == {"step": 1, "agent": "r1", "action_a": 0, "action_b": 1}
    assert cli(capsys, "diff", run, "10", "10")[0] == 1


def test_diff_across_runs_compares_by_name(run: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    # another run of the same walks, written again: the same episodes compare as identical across runs,
    # and two different episodes diverge where they do within one run
    other = str(write_walk_run(tmp_path / "again"))
    code, out, _ = cli(capsys, "diff", f"{run}:12", f"{other}:12", "--json")
    d = json.loads(out)
    assert code == 0 and d["identical"] and (d["run_a"], d["run_b"]) == (run, other)
    code, out, _ = cli(capsys, "diff", f"{run}:11", f"{other}:12", "--json")
    across = json.loads(out)
    code, out, _ = cli(capsys, "diff", run, "11", "12", "--json")
    within = json.loads(out)
    for key in ("rel_t", "t_a", "t_b", "first_action_difference", "outcome_a", "outcome_b"):
        assert across[key] == within[key], key
    assert [r["atom"] for r in across["only_in_b"]] == [r["atom"] for r in within["only_in_b"]] == ["move(r1)"]
    code, out, _ = cli(capsys, "diff", f"{run}:11", f"{other}:12")
    assert f"first divergence of the trace: 1 steps in (t=1 in episode {run}:11, t=1 in episode {other}:12)" in out
    assert cli(capsys, "diff", f"{run}:11", f"{other}:99")[0] == 1


def test_seal_command(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = write_walk_run(tmp_path / "walk")
    code, out, _ = cli(capsys, "seal", str(run))
    assert code == 0 and out.strip() == str(run / "run.duckdb")
    code, out, _ = cli(capsys, "sql", str(run / "run.duckdb"), "SELECT count(*) AS n FROM changes", "--format", "csv")
    assert out.split() == ["n", "40"]


def test_show_prints_metadata_program_scenario_and_counts(run: str, capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "show", run)
    assert code == 0
    lines = out.splitlines()
    assert lines[0] == "run walk: finished" and "  command   pytest walk" in lines
    assert "episodes  3 (1 loss, 1 truncated, 1 win)" in lines
    assert "rows      40 changes, 18 steps, 12 metrics, 4 rules, 6 facts, 14 atoms, 10 groundings" in lines
    assert "scenario  walk" in lines and "program   4 rules, 6 facts" in lines
    assert "  alarm: alarm(A) <-! agent(A), at(A,X), danger(X)" in lines
    code, out, _ = cli(capsys, "show", run, "--json")
    doc = json.loads(out)
    assert code == 0 and doc["run"]["seed"] == 7 and doc["run"]["config"] == {"worlds": 3}
    assert doc["episodes"]["by_outcome"] == {"loss": 1, "truncated": 1, "win": 1}
    assert [r["name"] for r in doc["rules"]] == ["go", "leave", "near", "alarm"]


def test_sql_list_needs_no_run(capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "sql", "--list")
    assert code == 0 and "episode_summary:" in out
    code, _, err = cli(capsys, "sql")
    assert code == 1 and "give a run and a SQL query" in err


def test_table_output_stops_at_the_default_limit_and_says_how_to_get_more(
        run: str, capsys: pytest.CaptureFixture) -> None:
    from tracelab.commands._output import DEFAULT_TABLE_ROWS
    code, out, err = cli(capsys, "sql", run, f"SELECT * FROM range({DEFAULT_TABLE_ROWS + 5}) r(i)")
    assert code == 0 and out.splitlines()[-1] == f"({DEFAULT_TABLE_ROWS} rows)"
    assert err.startswith(f"note: showing the first {DEFAULT_TABLE_ROWS} rows; --limit N shows more")
    code, out, err = cli(capsys, "sql", run, f"SELECT * FROM range({DEFAULT_TABLE_ROWS + 5}) r(i)",
                         "--limit", str(DEFAULT_TABLE_ROWS + 3))
    assert out.splitlines()[-1] == f"({DEFAULT_TABLE_ROWS + 3} rows)" and err == ""
    code, out, err = cli(capsys, "sql", run, f"SELECT * FROM range({DEFAULT_TABLE_ROWS}) r(i)")
    assert out.splitlines()[-1] == f"({DEFAULT_TABLE_ROWS} rows)" and err == ""


def test_csv_json_and_parquet_stream_every_row_across_batches(run: str, capsys: pytest.CaptureFixture,
                                                              tmp_path: Path) -> None:
    from tracelab.store.reader import BATCH_ROWS
    n = 2 * BATCH_ROWS + 10
    query = f"SELECT i, [i, i + 1] AS pair FROM range({n}) r(i) ORDER BY i"
    code, out, _ = cli(capsys, "sql", run, query, "--format", "csv")
    rows = out.splitlines()
    assert code == 0 and len(rows) == n + 1 and rows[1] == "0,\"[0,1]\"" and rows[-1].startswith(f"{n - 1},")
    code, out, _ = cli(capsys, "sql", run, query, "--format", "json", "--offset", str(BATCH_ROWS - 2),
                       "--limit", "5")
    assert [r["i"] for r in json.loads(out)] == list(range(BATCH_ROWS - 2, BATCH_ROWS + 3))
    target = tmp_path / "all.parquet"
    assert cli(capsys, "sql", run, query, "--format", "parquet", "-o", str(target))[0] == 0
    table = pq.read_table(target)
    assert table.num_rows == n and table.column("pair").to_pylist()[-1] == [n - 1, n]
    code, out, _ = cli(capsys, "sql", run, "SELECT 1 AS x WHERE false", "--format", "json")
    assert json.loads(out) == []
