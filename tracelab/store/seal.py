"""Seal a finished (or crashed) run: compact its Parquet parts into one DuckDB file, run.duckdb.

The file is built under a temp name and renamed into place, so a crash while sealing leaves the parts
untouched and the run readable; once run.duckdb exists, readers use it and the parts are removed.
Readers open on the parts meanwhile move to run.duckdb by themselves (reader.LiveRunConnection); a
query that was still to open a removed part fails once and reads the sealed file when run again
(reader.retrying). Under the writer lock, seal first removes what a killed writer or an earlier failed
seal left: temp files, and parts the manifest no longer lists."""
from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path

from tracelab.engine.duckdb_limits import exact_file
from tracelab.engine.safe_files import check_regular
from tracelab.store import layout
from tracelab.store.meta import meta_table, now_iso, open_writer_lock, read_meta, take_writer_lock, write_meta
from tracelab.store.parts import read_manifest, remove_unlisted
from tracelab.store.reader import _create_table, resolve_run
from tracelab.store.sandbox import lock_configuration, lock_down, sandbox_connection
from tracelab.store.schema import SEAL_ORDER, TABLES, VIEWS_SQL, empty_sql


def seal_run(run: str | Path, *, keep_parts: bool = False,
             on_table: Callable[[str], None] | None = None) -> Path:
    """Write <run>/run.duckdb from the parts and return its path (idempotent). Refuses while a writer
    holds the run. `on_table(name)` is called as each of the run's tables is copied (progress)."""
    run_dir = resolve_run(run)
    if not run_dir.is_dir():
        raise ValueError(f"{str(run_dir)!r} is not a run directory (a lone .duckdb file is already sealed)")
    if "?" in str(run_dir.resolve()):  # DuckDB 2.0 names the .wal of `a?b/run.duckdb` `a.wal?b/run.duckdb`
        raise ValueError(f"{str(run_dir)!r}: DuckDB cannot build a database file in a path with '?'; seal a "
                         "copy of the run in a folder without one (reading the run works as it is)")
    sealed = layout.sealed_path(run_dir)
    doc = read_meta(run_dir)
    with open_writer_lock(run_dir) as lock:
        take_writer_lock(run_dir, lock, doc, "sealing")
        if os.path.lexists(sealed):
            check_regular(sealed, follow_symlinks=False)  # the parts go only once the sealed file is one
        else:
            # We hold the writer lock, so a run still marked 'running' lost its writer.
            status = "crashed" if doc.get("status") == "running" else doc.get("status", "finished")
            parts = read_manifest(run_dir)  # checked before anything is deleted
            layout.remove_stale_temps(run_dir)
            remove_unlisted(run_dir)
            _build(run_dir, sealed, parts, {**doc, "status": status}, on_table)
            doc.update(status=status, sealed_at=now_iso())
            write_meta(run_dir, doc)
        if not keep_parts:
            shutil.rmtree(layout.parts_dir(run_dir), ignore_errors=True)
    return sealed


def _build(run_dir: Path, sealed: Path, parts: dict[str, list[Path]], doc: dict,
           on_table: Callable[[str], None] | None = None) -> None:
    """Build the sealed file from `parts` (the last flush; parts it does not list were never
    published). DuckDB creates the file and its .wal itself, so it builds them in a folder made new
    for it (mkdir fails if the name exists), where no file or link can be waiting, then the file is
    renamed into place."""
    work = layout.tmp_name(sealed)
    os.mkdir(work, 0o700)
    try:
        tmp = work / layout.SEALED
        # The sandbox's settings: the parts come from the run, which may come from anyone; this
        # connection reads them and writes only its own (already open) file.
        con = sandbox_connection(str(tmp))
        try:
            lock_down(con, [str(run_dir.resolve() / layout.PARTS) + "/"])
            lock_configuration(con)
            con.execute("CREATE SCHEMA raw")
            for t in TABLES:
                order = f" ORDER BY {SEAL_ORDER[t]}" if t in SEAL_ORDER else ""
                if not parts[t]:  # a table added after the run was written (schema.ADDED_TABLES)
                    con.execute(f"CREATE TABLE raw.{t} AS {empty_sql(t)}")
                else:
                    con.execute(f"CREATE TABLE raw.{t} AS SELECT * FROM read_parquet(?){order}",
                                [[exact_file(f) for f in parts[t]]])
                if on_table is not None:
                    on_table(t)
            _create_table(con, "raw.run", meta_table(doc, doc["status"]))
            con.execute(VIEWS_SQL)
            con.execute("CHECKPOINT")
        finally:
            con.close()
        os.replace(tmp, sealed)
    finally:
        shutil.rmtree(work, ignore_errors=True)
