"""The run catalog: every run under some directories, with its status (live, from the writer's lock and
pid, via run_info), command, scenario, episodes, change rows, size and start time.

`tracelab runs` prints it; the TUI's Runs screen shows it and refreshes it while runs grow. Counts are read
through the store's sandboxed query path, never by opening a run's files: the sealed runs' files attached
together on one sandboxed connection, each file's catalog checked as open_run checks it, and only the three
tables counted (not open_run's views: ~0.2 s of CPU a run); a live run through open_run + query_readonly."""
from __future__ import annotations

import datetime as _dt
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import duckdb

from tracelab.store import layout
from tracelab.store.reader import attach_sealed_file, open_run, query_readonly, retrying, run_info, sealed_file_of_run
from tracelab.store.sandbox import lock_down, sandbox_connection
from tracelab.store.sealed_catalog import check_sealed_catalog, entries_checked, read_sealed_catalogs

if TYPE_CHECKING:
    import pyarrow as pa

# deferred: pyarrow (listing runs as a text table needs none) and branch_origin (sql imports this module and needs
# none)

DEFAULT_ROOTS = (Path("runs"), Path("sample_runs"))
# RunSummary.as_row()'s columns, in the order `tracelab runs` prints them
# A row of the catalog (RunSummary.as_row()): its columns, and which are numbers.
ROW_COLUMNS: dict[str, bool] = {"name": False, "status": False, "episodes": True, "rows": True, "size": False,
                                "started": False, "scenario": False, "command": False, "path": False}


@dataclass
class RunSummary:
    path: Path
    name: str
    status: str                  # running | finished | failed | interrupted | crashed | unreadable
    command: str
    scenario: str
    episodes: int | None
    rows: int | None             # change rows
    size: int                    # bytes on disk
    started_at: _dt.datetime | None
    error: str = ""              # why the run could not be read (status 'unreadable')
    origin: str = ""             # a what-if branch's origin (branch_origin.Origin.describe), shown by its scenario

    def as_row(self) -> dict[str, Any]:
        scenario = f"{self.scenario} ({self.origin})" if self.scenario and self.origin else self.scenario or self.origin
        return {"name": self.name, "status": self.status, "episodes": self.episodes, "rows": self.rows,
                "size": human_size(self.size), "started": _time_text(self.started_at),
                "scenario": scenario, "command": self.command, "path": str(self.path)}


def catalog_table(rows: Sequence[dict[str, Any]]) -> "pa.Table":
    """Rows of RunSummary.as_row() as an Arrow table (built from buffers: Table.from_pylist imports pandas)."""
    import pyarrow as pa

    from tracelab.store.arrow_build import table_from_rows
    schema = pa.schema([(name, pa.int64() if number else pa.string()) for name, number in ROW_COLUMNS.items()])
    return table_from_rows(rows, schema)


def short_command(command: str) -> str:
    """The command as typed: `tracelab ...` without the interpreter's path to the script."""
    words = command.split()
    if words and words[0].endswith("/tracelab"):
        words[0] = "tracelab"
    return " ".join(words)


def human_size(n: int) -> str:
    size = float(n)
    for unit in ("B", "KB", "MB", "GB"):
        if size < 1024 or unit == "GB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{n} B"


def _time_text(t: _dt.datetime | None) -> str:
    return "" if t is None else t.strftime("%Y-%m-%d %H:%M:%S")


def _parse_time(value: Any) -> _dt.datetime | None:
    if value is None or isinstance(value, _dt.datetime):
        return value
    try:
        t = _dt.datetime.fromisoformat(str(value))
    except ValueError:
        return None
    return t.astimezone(_dt.UTC).replace(tzinfo=None) if t.tzinfo else t


def is_run(path: Path) -> bool:
    """A run directory (it has a meta.json: whatever it is, a broken one is listed as unreadable) or a
    lone .duckdb file."""
    return (path.is_dir() and os.path.lexists(path / layout.META)) or (
        path.is_file() and path.suffix == ".duckdb")


def find_runs(roots: Iterable[str | Path]) -> list[Path]:
    """The runs given: each root that is a run itself, else the runs directly inside it; sorted by
    path within each root, roots in the order given, no path twice."""
    found: list[Path] = []
    seen: set[Path] = set()
    for root in map(Path, roots):
        if is_run(root):
            candidates = [root]
        elif root.is_dir():
            candidates = sorted(p for p in root.iterdir() if is_run(p))
        else:
            candidates = []
        for p in candidates:
            key = p.resolve()
            if key not in seen:
                seen.add(key)
                found.append(p)
    return found


def _disk_size(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    total = 0
    for folder, _, files in os.walk(path):  # links are not followed: the run's own bytes
        for name in files:
            try:
                total += os.lstat(os.path.join(folder, name)).st_size
            except OSError:  # a part deleted by compaction while we walked
                pass
    return total


SEALED_PER_CONNECTION = 64  # sealed files attached to one connection at most (each holds its catalog in memory)


def _counts_sql(raw: str) -> str:
    return (f"SELECT (SELECT count(*) FROM (SELECT episode FROM {raw}.episode_begin UNION "
            f"SELECT episode FROM {raw}.episode_end)), (SELECT count(*) FROM {raw}.changes)")


def _counts(path: Path) -> tuple[int, int]:
    con = open_run(path)
    try:
        eps, rows = retrying(lambda: query_readonly(con, _counts_sql("raw")).fetchall())[0]
        return int(eps), int(rows)
    finally:
        con.close()


def _sealed_counts(sealed: dict[Path, Path]) -> dict[Path, tuple[int, int] | Exception]:
    """Run -> (episodes, change rows) of runs with a sealed file (run -> its file), or why it could not be
    read; the files attached read-only on one sandboxed connection, each file's catalog checked before
    anything in it is read."""
    found: dict[Path, tuple[int, int] | Exception] = {}
    runs = list(sealed)
    for start in range(0, len(runs), SEALED_PER_CONNECTION):
        con = sandbox_connection()
        try:
            attached, identities = {}, {}
            for i, run in enumerate(runs[start:start + SEALED_PER_CONNECTION]):
                try:
                    identities[run] = attach_sealed_file(con, sealed[run], f"store_{i}")
                    attached[run] = f"store_{i}"
                except duckdb.InterruptException:
                    raise
                except Exception as e:  # noqa: BLE001 - one broken run must not hide the others
                    found[run] = e
            lock_down(con)
            catalogs = read_sealed_catalogs(con, list(attached.values()),  # one pass for every file
                                            [attached[r] for r in attached if entries_checked(identities[r])])
            for run, database in attached.items():
                try:
                    check_sealed_catalog(con, database, sealed[run], catalogs[database], identities[run])
                    eps, rows = con.execute(_counts_sql(f"{database}.raw")).fetchall()[0]
                    found[run] = (int(eps), int(rows))
                except duckdb.InterruptException:
                    raise
                except Exception as e:  # noqa: BLE001
                    found[run] = e
        finally:
            con.close()
    return found


def summarize_run(path: Path, counts: tuple[int, int] | Exception | None = None) -> RunSummary:
    """One run's summary; a run that cannot be read is listed as 'unreadable' with the reason. `counts`:
    its episodes and change rows as _sealed_counts found them (None: read them here)."""
    name = path.stem if path.is_file() else path.name
    try:
        info = run_info(path)
        if isinstance(counts, Exception):
            raise counts
        episodes, rows = counts or _counts(path)
    except duckdb.InterruptException:
        raise  # stopped by the user (Ctrl-C): not a broken run
    except Exception as e:  # noqa: BLE001 - one broken run must not hide the others
        return RunSummary(path, name, "unreadable", "", "", None, None, _disk_size(path), None,
                          error=str(e).splitlines()[0] if str(e) else type(e).__name__)
    meta = info.meta
    config = meta.get("config")
    from tracelab.store.branch_origin import branch_origin
    origin = branch_origin(config) if isinstance(config, dict) else None
    return RunSummary(path, name, info.status, short_command(str(meta.get("command") or "")),
                      str(meta.get("scenario") or ""), episodes, rows, _disk_size(path),
                      _parse_time(meta.get("started_at")), origin=origin.describe() if origin else "")


def list_runs(roots: Sequence[str | Path] = DEFAULT_ROOTS) -> list[RunSummary]:
    """Every run under `roots` (directories of runs, or runs themselves), newest first; ties by path."""
    paths = find_runs(roots)
    sealed = {}
    for p in paths:
        try:
            file = sealed_file_of_run(p)
        except Exception:  # noqa: BLE001 - summarize_run says why it cannot be read
            file = None
        if file is not None:
            sealed[p] = file
    counts = _sealed_counts(sealed)
    runs = [summarize_run(p, counts.get(p)) for p in paths]
    oldest = _dt.datetime.min
    runs.sort(key=lambda r: str(r.path))
    runs.sort(key=lambda r: r.started_at or oldest, reverse=True)
    return runs
