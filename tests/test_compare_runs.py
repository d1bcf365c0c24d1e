"""Several training runs side by side (issue 27 §3): `tracelab compare RUN...`, read through the store's
sandboxed reader, on two real tiny trainings (seconds each) that differ in their seed and learning rate."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from tracelab.cli import main
from tracelab.store import open_run
from train_helpers import tiny_training_run

ROOT = Path(__file__).resolve().parent.parent
PLAY_RUN = ROOT / "sample_runs" / "base"
REASONING_RUN = ROOT / "sample_runs" / "supply-chain"


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two finished trainings of the tiny walk (400 steps: evaluations at 200 and 400)."""
    root = tmp_path_factory.mktemp("compare")
    return [tiny_training_run(root / "seed1", steps=400, seed=1, trace_eval_games=0),
            tiny_training_run(root / "seed2", steps=400, seed=2, lr=1e-3, trace_eval_games=0)]


def last_values(run: Path) -> dict[str, float]:
    con = open_run(run)
    try:
        return dict(con.execute("SELECT name, arg_max(value, step) FROM metrics GROUP BY name").fetchall())
    finally:
        con.close()


def table_rows(text: str) -> dict[str, list[str]]:
    """The text table as key -> cells (columns split on two spaces or more)."""
    import re
    lines = text.splitlines()
    return {cells[0]: cells[1:] for cells in (re.split(r"\s{2,}", ln.strip()) for ln in lines[2:-1])}


def test_compare_prints_final_metrics_and_only_the_config_keys_that_differ(two_runs, capsys):
    a, b = two_runs
    assert main(["compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    header = out.splitlines()[0].split()
    assert header == ["key", str(a), str(b)]                      # runs named by their paths
    rows = table_rows(out)
    assert rows["status"] == ["finished", "finished"] and rows["last step"] == ["400", "400"]
    config_rows = {k for k in rows if k.startswith("config ")}
    assert config_rows == {"config lr", "config seed"}            # batch, scenario, ... are the same
    assert rows["config lr"] == ["0.003", "0.001"] and rows["config seed"] == ["1", "2"]
    for run, column in ((a, 0), (b, 1)):
        final = last_values(run)
        assert float(rows["eval/win_rate"][column]) == pytest.approx(final["eval/win_rate"], abs=5e-4)
        assert float(rows["loss"][column]) == pytest.approx(final["loss"], rel=1e-3)
        assert rows["eval/games"][column] == "8"
        best, at = rows["eval/win_rate (best)"][column].split(" @")
        assert int(at) in (200, 400)


def test_compare_as_json_keeps_full_precision(two_runs, capsys):
    a, b = two_runs
    assert main(["compare", str(a), str(b), "--format", "json"]) == 0
    rows = {r["key"]: r for r in json.loads(capsys.readouterr().out)}
    assert float(rows["loss"][str(a)]) == last_values(a)["loss"]


@pytest.mark.parametrize("other, says", [
    (PLAY_RUN, "is a play run (games, no training metrics): compare puts training runs side by side"),
    (REASONING_RUN, "is a reasoning run (a trace, no training metrics)"),
])
def test_compare_refuses_a_run_that_is_not_a_training_run_in_one_line(two_runs, capsys, other, says):
    assert main(["compare", str(two_runs[0]), str(other)]) == 1
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert err.startswith(f"tracelab: error: {str(other)!r} {says}") and "\n" not in err
    assert "tracelab diff RUN_A RUN_B" in err and captured.out == ""


def test_compare_names_an_unknown_or_broken_run_in_one_line(two_runs, tmp_path, capsys):
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "meta.json").write_text("{")
    for bad, says in ((tmp_path / "nope", "no run"), (tmp_path / "broken", "meta.json:")):
        assert main(["compare", str(two_runs[0]), str(bad)]) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("tracelab: error: ") and says in err and str(bad.name) in err and "\n" not in err
    assert main(["compare", str(two_runs[0]), str(two_runs[0])]) == 1
    assert "is given twice" in capsys.readouterr().err
