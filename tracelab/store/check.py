"""Check a run's files (`tracelab check RUN`), and repair a live run (`--repair`): damaged parts go to the
run's quarantine/ folder and leave the manifest, so the rest of the run reads again; leftovers of a
killed writer or a failed seal (temp files, parts the manifest no longer lists) are removed.

Every part the manifest lists is read in full with pyarrow (every page decoded, so a corrupt page is
found, not only a corrupt footer) and its columns compared with the table's schema. A sealed run is
checked by reading every stored table through the sandboxed reader."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow.compute as pc
import pyarrow.parquet as pq

from tracelab.store import layout
from tracelab.store.meta import open_writer_lock, read_meta, take_writer_lock
from tracelab.store.parts import (
    manifest_flushes,
    read_manifest,
    remove_unlisted,
    write_empty_part,
    write_manifest_lists,
)
from tracelab.store.reader import STORED_COLUMNS, _sealed_file, open_run, resolve_run
from tracelab.store.schema import ADDED_COLUMNS, SCHEMAS


@dataclass
class DamagedPart:
    table: str
    path: Path          # relative to the run directory
    error: str
    episodes: str       # which episodes it held, in words


@dataclass
class CheckReport:
    run: Path
    sealed: bool
    parts: int = 0
    rows: int = 0
    damaged: list[DamagedPart] = field(default_factory=list)
    error: str | None = None              # a sealed file that does not read
    quarantined: list[Path] = field(default_factory=list)
    unlisted_bytes: int = 0
    temps: int = 0

    @property
    def ok(self) -> bool:
        return self.error is None and (not self.damaged or bool(self.quarantined))


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0] if text else ''}"


def _describe(episodes: list[int]) -> str:
    if not episodes:
        return "no episode rows"
    if len(episodes) <= 12:
        return "episode" + ("s " if len(episodes) > 1 else " ") + ", ".join(map(str, episodes))
    return f"{len(episodes)} episodes from {episodes[0]} to {episodes[-1]}"


def episodes_held(path: Path, table: str) -> str:
    """Which episodes a (possibly damaged) part held: from its episode column if that still reads, else
    from the row groups' statistics in its footer."""
    if "episode" not in SCHEMAS[table].names:
        return "no episodes (program, vocabulary or groundings rows)"
    try:
        column = pq.read_table(path, columns=["episode"]).column(0)
        return _describe(sorted(e for e in pc.unique(column).to_pylist() if e is not None))
    except Exception:  # noqa: BLE001 - damaged: fall back to the footer
        pass
    try:
        meta = pq.ParquetFile(path).metadata
        i = meta.schema.names.index("episode")
        stats = [meta.row_group(g).column(i).statistics for g in range(meta.num_row_groups)]
        lo = min(s.min for s in stats if s is not None and s.has_min_max)
        hi = max(s.max for s in stats if s is not None and s.has_min_max)
        return f"episodes {lo} to {hi} (from its statistics)"
    except Exception:  # noqa: BLE001 - nothing readable is left
        return "unknown episodes (its footer does not read)"


def verify_part(path: Path, table: str) -> tuple[int, str | None]:
    """(rows, None) for a sound part, (0, error) for a damaged one."""
    try:
        data = pq.read_table(path)
    except Exception as e:  # noqa: BLE001 - any failure to read is damage
        return 0, _one_line(e)
    # a part written before a column was added (schema.ADDED_COLUMNS) lacks it, and reads without it
    expected = [c for c in SCHEMAS[table].names
                if c in data.schema.names or c not in ADDED_COLUMNS.get(table, {})]
    if data.schema.names != expected:
        return 0, f"its columns {data.schema.names} are not {SCHEMAS[table].names}"
    return data.num_rows, None


def _check_parts(run_dir: Path, report: CheckReport) -> dict[str, list[str]]:
    """Fill report.parts/rows/damaged; return the manifest's entries without the damaged parts."""
    keep: dict[str, list[str]] = {}
    parts_dir = run_dir.resolve() / layout.PARTS
    for table, files in read_manifest(run_dir).items():
        keep[table] = []
        for path in files:
            report.parts += 1
            rows, error = verify_part(path, table)
            entry = str(path.relative_to(parts_dir))
            if error is not None and not path.exists() and path not in read_manifest(run_dir)[table]:
                continue  # a live writer merged it away (its grace period ended) while we read
            if error is None:
                report.rows += rows
                keep[table].append(entry)
            else:
                report.damaged.append(DamagedPart(table, Path(layout.PARTS) / entry, error,
                                                  episodes_held(path, table)))
    return keep


def _check_sealed(run: Path, report: CheckReport) -> None:
    try:
        con = open_run(run)
        try:
            for table in STORED_COLUMNS:
                # hash of every row: every column of every row group is read and decoded
                n, _ = con.execute(f"SELECT count(*), sum(hash(r)) FROM raw.{table} r").fetchone()
                report.rows += n
                report.parts += 1
        finally:
            con.close()
    except Exception as e:  # noqa: BLE001 - a sealed file that does not read is the finding
        report.error = _one_line(e)


def check_run(run: str | Path, *, repair: bool = False) -> CheckReport:
    """Verify every part of the run (or its sealed file). With repair, under the writer lock: move
    damaged parts to <run>/quarantine/<table>/, rewrite the manifest without them, remove temp files
    and parts the manifest no longer lists."""
    run_dir = resolve_run(run)
    if _sealed_file(run_dir) is not None:
        report = CheckReport(run_dir, sealed=True)
        _check_sealed(run_dir, report)
        return report
    doc = read_meta(run_dir)
    report = CheckReport(run_dir, sealed=False)
    if not repair:
        _check_parts(run_dir, report)
        return report
    with open_writer_lock(run_dir) as lock:
        take_writer_lock(run_dir, lock, doc, "repairing it")
        keep = _check_parts(run_dir, report)
        if report.damaged:
            _repair(run_dir, report, keep)
        report.temps = layout.remove_stale_temps(run_dir)
        report.unlisted_bytes = remove_unlisted(run_dir)
    return report


def _repair(run_dir: Path, report: CheckReport, keep: dict[str, list[str]]) -> None:
    """All or nothing: the new files (empty parts, the manifest without the damaged parts) are written
    first, and a failure there (a full disk) removes what it wrote and leaves the run as it was; only
    then are the damaged parts, no longer listed, moved to the quarantine (renames, which need no
    space: should one fail, the run reads without that part all the same)."""
    # every target checked (no link on the way out of the run) before anything is written or moved
    targets = [layout.run_path(run_dir, layout.QUARANTINE, part.table, part.path.name)
               for part in report.damaged]
    written: list[Path] = []
    try:
        for table, entries in keep.items():
            if not entries:  # every table keeps one file that carries its schema
                entries.append(write_empty_part(run_dir, table))
                written.append(layout.run_path(run_dir, layout.PARTS, *entries[-1].split("/")))
        write_manifest_lists(run_dir, keep, manifest_flushes(run_dir))
    except OSError as e:
        for path in written:
            path.unlink(missing_ok=True)
        raise RuntimeError(f"{run_dir}: repair not made, the run is as it was: {e.strerror or e} "
                           f"({e.filename or 'writing the manifest'})") from e
    for part, target in zip(report.damaged, targets):
        layout.make_run_dirs(run_dir, layout.QUARANTINE, part.table)
        if os.path.lexists(run_dir / part.path):
            os.replace(run_dir / part.path, target)
        report.quarantined.append(target.relative_to(run_dir))
