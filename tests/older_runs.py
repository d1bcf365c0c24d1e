"""A run as tracelab wrote it before it recorded the agent's half (decisions, reward terms, action and
observation names): a copy of a sealed sample run without those tables, for the tests that older runs
still read (as having none)."""
from __future__ import annotations

import shutil
from pathlib import Path

import duckdb

AGENT_TABLES = ("decisions", "reward_terms", "action_names", "observation_names")


def older_run(sealed: Path, into: Path) -> Path:
    """`sealed` (a run folder holding run.duckdb) copied to `into` with the agent's tables dropped."""
    into.mkdir(parents=True)
    for name in ("run.duckdb", "meta.json"):
        shutil.copy(sealed / name, into / name)
    con = duckdb.connect(str(into / "run.duckdb"))
    try:
        views = [r[0] for r in con.execute("SELECT view_name FROM duckdb_views() WHERE NOT internal").fetchall()]
        for view in views:          # the views are made again when the run is opened
            con.execute(f'DROP VIEW IF EXISTS "{view}"')
        for table in AGENT_TABLES:
            con.execute(f"DROP TABLE IF EXISTS raw.{table}")
    finally:
        con.close()
    return into
