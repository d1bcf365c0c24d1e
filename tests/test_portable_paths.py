"""A run names the files it was made from by portable paths (tracelab/store/portable_paths.py): one made in
one directory and moved to another (a clone's sample_runs/) shows no path of the place it was made in."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import duckdb
import pytest
from store_helpers import WALK_RULES, write_walk_run

from tracelab import RULES_DIR
from tracelab.cli import main
from tracelab.store.meta import read_meta
from tracelab.store.writer import TraceWriter


def cli(capsys: pytest.CaptureFixture, *argv: str) -> str:
    code = main(list(argv))
    out = capsys.readouterr()
    assert code == 0, out.err
    return out.out + out.err


def stored_text(run: Path) -> str:
    """Every string a run keeps: meta.json and, sealed, each string column of run.duckdb."""
    texts = [(run / "meta.json").read_text()]
    if (run / "run.duckdb").exists():
        con = duckdb.connect(str(run / "run.duckdb"), read_only=True)
        columns = con.execute("SELECT table_name, column_name FROM information_schema.columns "
                              "WHERE table_schema = 'raw' AND data_type = 'VARCHAR'").fetchall()
        for table, column in columns:
            texts += [v for (v,) in con.execute(f'SELECT DISTINCT "{column}" FROM raw."{table}"').fetchall() if v]
        con.close()
    return "\n".join(texts)


def test_a_played_run_moved_elsewhere_names_no_path_of_where_it_was_made(
        tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch) -> None:
    made = tmp_path / "made-here"
    made.mkdir()
    monkeypatch.chdir(made)  # as sample_runs/regenerate.sh makes them: --run NAME in the runs' folder
    cli(capsys, "play", "--scenario", "base", "--episodes", "1", "--seed", "1", "--run", "r")
    cli(capsys, "seal", "r")
    moved = tmp_path / "elsewhere"
    shutil.move(made, moved)
    monkeypatch.chdir(tmp_path)
    run = moved / "r"
    shown = [cli(capsys, "show", str(run)), cli(capsys, "show", "--json", str(run)),
             cli(capsys, "runs", str(moved)), stored_text(run)]
    for text in shown:
        assert str(made) not in text and str(RULES_DIR) not in text
    assert "rules     rules/gridworld/game.rules" in shown[0] and "spec      rules/gridworld/war.toml" in shown[0]
    assert "/" not in read_meta(run)["argv"][0]  # the program's name, not where it was installed


def test_files_inside_the_run_are_named_from_the_run(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "made-here" / "walk"
    (run / "program").mkdir(parents=True)
    rules = run / "program" / "walk.rules"
    shutil.copy(WALK_RULES, rules)
    write_walk_run(run, rules)
    other = tmp_path / "made-here" / "other"
    spec = RULES_DIR / "gridworld" / "war.toml"
    config = {"policy": str(rules.parent), "env": {"name": str(spec), "kwargs": {}},
              "env_id": "tracelab/GridWar-base-v0", "elsewhere": str(tmp_path / "not-a-run-file")}
    with TraceWriter(other, {"config": config}) as w:
        w.add_config({"spec_path": str(spec)})
    assert read_meta(run)["rule_files"][0]["path"] == "{run}/program/walk.rules"
    assert read_meta(other)["config"] == {**config, "policy": str(rules.parent),  # another run's: as given
                                          "env": {"name": "rules/gridworld/war.toml", "kwargs": {}},
                                          "spec_path": "rules/gridworld/war.toml"}
    moved = tmp_path / "elsewhere"
    shutil.move(tmp_path / "made-here", moved)
    cli(capsys, "seal", str(moved / "walk"))
    shown = cli(capsys, "show", "--json", str(moved / "walk"))
    assert str(tmp_path) not in shown and str(tmp_path) not in stored_text(moved / "walk")
    assert {r["file"] for r in json.loads(shown)["rules"]} == {"{run}/program/walk.rules"}
