"""A live run's parts checked (`tracelab check`): every part the manifest lists is read in full with
pyarrow (every page decoded, so a corrupt page is found, not only a corrupt footer) and its columns
compared with the table's schema; and repaired (`--repair`, tracelab.store.check)."""
from __future__ import annotations

import os
from pathlib import Path

import pyarrow.compute as pc
import pyarrow.parquet as pq

from tracelab.store import layout
from tracelab.store.check_report import CheckReport, DamagedPart, one_line
from tracelab.store.parts import manifest_flushes, read_manifest, write_empty_part, write_manifest_lists
from tracelab.store.schema import ADDED_COLUMNS, COLUMNS


def _describe(episodes: list[int]) -> str:
    if not episodes:
        return "no episode rows"
    if len(episodes) <= 12:
        return "episode" + ("s " if len(episodes) > 1 else " ") + ", ".join(map(str, episodes))
    return f"{len(episodes)} episodes from {episodes[0]} to {episodes[-1]}"


def episodes_held(path: Path, table: str) -> str:
    """Which episodes a (possibly damaged) part held: from its episode column if that still reads, else
    from the row groups' statistics in its footer."""
    if "episode" not in COLUMNS[table]:
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
        return 0, one_line(e)
    # a part written before a column was added (schema.ADDED_COLUMNS) lacks it, and reads without it
    expected = [c for c in list(COLUMNS[table])
                if c in data.schema.names or c not in ADDED_COLUMNS.get(table, {})]
    if data.schema.names != expected:
        return 0, f"its columns {data.schema.names} are not {list(COLUMNS[table])}"
    return data.num_rows, None


def check_parts(run_dir: Path, report: CheckReport) -> dict[str, list[str]]:
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


def repair_parts(run_dir: Path, report: CheckReport, keep: dict[str, list[str]]) -> None:
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
