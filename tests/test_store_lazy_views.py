"""A sealed run's views are made as statements name them (tracelab.store.reader.SealedRunConnection):
a command pays for the views it reads, and every statement sees what the whole set of views gives."""
from __future__ import annotations

from pathlib import Path

import duckdb
import pytest

from tracelab.store.reader import open_run, query_readonly
from tracelab.store.schema import STORED_COLUMNS, VIEW_NAMES

RUNS = Path(__file__).resolve().parents[1] / "sample_runs"
MADE = "SELECT schema_name || '.' || view_name FROM duckdb_views() WHERE database_name = 'memory' ORDER BY 1"


def made(con: object) -> list[str]:
    """The views the connection holds now, read on the DuckDB connection underneath (reading them through
    the run's connection would make them all)."""
    return [v for (v,) in con._con.execute(MADE).fetchall()]  # type: ignore[attr-defined]


def test_a_statement_makes_the_views_it_names_and_what_they_read() -> None:
    con = open_run(RUNS / "base-train")
    assert made(con) == ["raw.run"]
    assert query_readonly(con, "SELECT count(*) FROM rewards").fetchall()[0][0] > 0
    assert made(con) == ["main.rewards", "raw.reward_terms", "raw.run"]
    con.execute("SELECT count(*) FROM action_values").fetchall()
    assert set(made(con)) == {"main.rewards", "main.decisions", "main.action_values", "raw.reward_terms",
                              "raw.run", "raw.decisions", "raw.action_names"}
    con.close()


@pytest.mark.parametrize("first", ["SHOW TABLES", "SELECT table_name FROM information_schema.tables",
                                   "SELECT view_name FROM duckdb_views()", "SELECT name FROM (SHOW ALL TABLES)"])
def test_a_statement_that_may_list_the_views_sees_them_all(first: str) -> None:
    con = open_run(RUNS / "advanced")
    listed = {row[0] for row in query_readonly(con, first).fetchall()}
    assert set(VIEW_NAMES) <= listed, first
    assert len(made(con)) == len(VIEW_NAMES) + len(STORED_COLUMNS)
    con.close()


def test_a_misspelt_name_gets_the_did_you_mean_of_the_whole_set() -> None:
    con = open_run(RUNS / "advanced")
    with pytest.raises(duckdb.CatalogException, match='Did you mean "firings"'):
        query_readonly(con, "SELECT * FROM firngs")
    con.close()


def test_other_uses_of_the_connection_get_every_view() -> None:
    con = open_run(RUNS / "advanced")
    cursor = con.cursor()   # a thread's own cursor runs statements the run's connection does not see
    assert cursor.execute("SELECT count(*) FROM firings").fetchall()[0][0] > 0
    con.close()


def test_the_rows_are_the_same_as_through_every_view() -> None:
    lazy, every = open_run(RUNS / "advanced"), open_run(RUNS / "advanced")
    every.cursor()
    for view in VIEW_NAMES:
        sql = f"SELECT * FROM {view} ORDER BY ALL LIMIT 50"
        assert lazy.execute(sql).fetchall() == every.execute(sql).fetchall(), view
    lazy.close()
    every.close()
