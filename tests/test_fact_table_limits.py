"""A fact table from a stranger is read by DuckDB under the same memory bound as a query on a run
(engine/duckdb_limits.py), never DuckDB's default of 80% of the machine, and never spills into the
working folder: a table too big for the bound is refused in one line naming the setting that raises it."""
from __future__ import annotations

from pathlib import Path

import pytest

from tracelab.cli import main
from tracelab.engine import load_fact_table


def a_big_table(folder: Path, rows: int = 300_000) -> Path:
    table = folder / "t.csv"
    lines = ["atom,lower,upper,start,end"] + [f'"link(node{i},node{i + 1})",1,1,0,0' for i in range(rows)]
    table.write_text("\n".join(lines) + "\n")
    return table


def test_a_fact_table_past_the_memory_bound_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    table = a_big_table(tmp_path)
    (tmp_path / "p.rules").write_text("seen(Y) <-0 link(X,Y)\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("TRACELAB_QUERY_MEMORY", "16M")
    code = main(["reason", "p.rules", "--facts-table", str(table), "--steps", "1"])
    err = capsys.readouterr().err
    assert code == 1
    assert len(err.strip().splitlines()) == 1, err
    assert "t.csv" in err and "16 MiB" in err and "TRACELAB_QUERY_MEMORY" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.rules", "t.csv"]  # no spill folder left here


def test_the_default_bound_reads_the_same_table(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("TRACELAB_QUERY_MEMORY", raising=False)
    g = load_fact_table(a_big_table(tmp_path, rows=20_000))
    assert len(g.nodes) == 20_001 and len(g.facts) == 20_000
