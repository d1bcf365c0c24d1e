"""A live run's Parquet parts and the manifest that says which of them make up the run.

Layout of parts/:
  <table>/00000042.parquet ...   immutable parts (temp name, then rename; a file never changes once named)
  manifest.json                  for every table, the parts that hold its rows now (replaced atomically)
Readers query exactly the files the manifest lists, never a directory listing: DuckDB lists a glob's
directory and then stats each entry, so a listing taken while parts were being merged could silently
drop rows (seen: a reader got only the big parts of a table, without the part they had just been merged
into). One manifest for all tables also gives a reader one consistent moment across tables.

A publication writes one new part per table with rows; then the writer replaces the manifest. When a
table holds `compact_files` small parts (< part_rows rows), they are merged into one new part and leave
the table's list; their files are deleted `grace_seconds` later, so a reader still holding the previous
manifest can finish its query. A crash before the manifest is replaced leaves parts nobody lists:
invisible and harmless (seal ignores them and removes parts/)."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path, PurePosixPath

import pyarrow as pa
import pyarrow.parquet as pq

from tracelab.store import layout
from tracelab.store.schema import SCHEMAS

ROW_GROUP_ROWS = 131_072
MANIFEST_FORMAT = "tracelab-parts/1"


class TableParts:
    """One table's parts: writes new ones, merges small ones, and knows which files hold the table."""

    def __init__(self, run_dir: Path, table: str, part_rows: int, compact_files: int = 64,
                 grace_seconds: float = 30.0, compression: str = "zstd") -> None:
        if compact_files < 2:
            raise ValueError(f"compact_files must be >= 2, got {compact_files}")
        self.table = table
        self.schema = SCHEMAS[table]
        self.root = layout.table_dir(run_dir, table)
        self.part_rows = part_rows
        self.compact_files = compact_files
        self.grace_seconds = grace_seconds
        self.compression = compression
        self._next_file = 0
        self._small: list[str] = []   # listed parts with fewer than part_rows rows, oldest first
        self._big: list[str] = []
        self._retired: list[tuple[float, list[str]]] = []
        self.rows_published = 0
        self.files_written = 0
        self.compactions = 0
        self.root.mkdir(parents=True, exist_ok=True)
        # An empty first part, so that every table has a file that carries its schema.
        self._add(self._write(self.schema.empty_table()), 0)

    @property
    def files(self) -> list[str]:
        """The table's parts now, as paths relative to parts/ (the manifest's form)."""
        return [f"{self.table}/{name}" for name in (*self._big, *self._small)]

    def _write(self, table: pa.Table) -> str:
        name = layout.part_name(self._next_file)
        self._next_file += 1
        final = self.root / name
        tmp = layout.tmp_name(final)
        pq.write_table(table, tmp, compression=self.compression, row_group_size=ROW_GROUP_ROWS)
        os.replace(tmp, final)
        self.files_written += 1
        return name

    def _add(self, name: str, rows: int) -> None:
        (self._big if rows >= self.part_rows else self._small).append(name)

    def publish(self, tables: list[pa.Table]) -> int:
        """Write these rows as a new part (merging small parts when there are enough) and list it; readers
        see it once the writer replaces the manifest. Returns how many rows were written."""
        n = sum(t.num_rows for t in tables)
        if n == 0:
            return 0
        table = pa.concat_tables(tables) if len(tables) > 1 else tables[0]
        self._add(self._write(table), n)
        self.rows_published += n
        if len(self._small) >= self.compact_files:
            self._compact()
        self._drop_retired()
        return n

    def _compact(self) -> None:
        merged = pa.concat_tables([pq.read_table(self.root / name, schema=self.schema)
                                   for name in self._small])
        merged_name = self._write(merged)
        self._retired.append((time.monotonic(), self._small))
        self._small = []
        self._add(merged_name, merged.num_rows)
        self.compactions += 1

    def _drop_retired(self) -> None:
        now = time.monotonic()
        while self._retired and now - self._retired[0][0] >= self.grace_seconds:
            for name in self._retired.pop(0)[1]:
                (self.root / name).unlink(missing_ok=True)


def write_manifest(run_dir: Path, parts: dict[str, TableParts], flushes: int) -> None:
    """Replace parts/manifest.json with the tables' current parts: the moment readers see."""
    write_manifest_lists(run_dir, {name: p.files for name, p in parts.items()}, flushes)


def write_manifest_lists(run_dir: Path, files: dict[str, list[str]], flushes: int) -> None:
    """Replace parts/manifest.json: for every table, its parts as paths relative to parts/."""
    doc = {"format": MANIFEST_FORMAT, "flushes": flushes, "tables": files}
    layout.replace_atomically(json.dumps(doc).encode(), layout.manifest_path(run_dir))


def manifest_flushes(run_dir: Path) -> int:
    """How many flushes the manifest records (read_manifest has checked the rest)."""
    return int(json.loads(layout.manifest_path(run_dir).read_text()).get("flushes", 0))


def write_empty_part(run_dir: Path, table: str) -> str:
    """A new part with no rows (it carries the table's schema), named after the table's highest part;
    returns its manifest entry."""
    directory = layout.table_dir(run_dir, table)
    numbers = [int(p.stem) for p in directory.glob(f"*{layout.PART_SUFFIX}") if p.stem.isdigit()]
    final = directory / layout.part_name(max(numbers, default=-1) + 1)
    tmp = layout.tmp_name(final)
    pq.write_table(SCHEMAS[table].empty_table(), tmp)
    os.replace(tmp, final)
    return f"{table}/{final.name}"


def read_manifest(run_dir: Path) -> dict[str, list[Path]]:
    """For every table, the absolute paths of the parts that hold its rows now. Refuses a manifest that
    names other tables or files outside parts/."""
    path = layout.manifest_path(run_dir)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"{str(run_dir)!r} has no {layout.PARTS}/{layout.MANIFEST}: not a "
                                "tracelab run directory, or one whose writer died while creating it") from None
    if doc.get("format") != MANIFEST_FORMAT:
        raise ValueError(f"{str(path)!r}: unknown manifest format {doc.get('format')!r}")
    base = path.parent.resolve()
    if base != run_dir.resolve() / layout.PARTS:
        raise ValueError(f"{str(path.parent)!r} is a link to {str(base)!r}: a run's parts/ must be a "
                         "directory inside the run")
    tables = doc.get("tables")
    if not isinstance(tables, dict) or set(tables) != set(SCHEMAS) \
            or not all(isinstance(files, list) for files in tables.values()):
        raise ValueError(f"{str(path)!r}: 'tables' must list the parts of exactly the tables "
                         f"{', '.join(SCHEMAS)}")
    return {name: [_part_path(path, base, f) for f in tables[name]] for name in SCHEMAS}


def _part_path(manifest: Path, base: Path, entry: object) -> Path:
    """A manifest entry as an absolute path, refused unless it names a file inside parts/: a relative
    path without '..' that, symlinks resolved, stays there (a run from elsewhere must not make a reader
    open other files)."""
    if not isinstance(entry, str) or not entry or entry.startswith("/") or "\\" in entry \
            or ".." in PurePosixPath(entry).parts:
        raise ValueError(f"{str(manifest)!r} lists {entry!r}: parts must be relative paths inside the "
                         "run's parts/ directory")
    full = base / entry
    if not full.resolve().is_relative_to(base):
        raise ValueError(f"{str(manifest)!r} lists {entry!r}, a link to {str(full.resolve())!r} outside "
                         "the run's parts/ directory")
    return full


def remove_unlisted(run_dir: Path) -> int:
    """Delete the parts the manifest does not list: merged parts a killed writer had not yet removed and
    parts written after its last manifest (only while holding the writer lock: a live writer's retired
    parts are still being read). Returns how many bytes were freed."""
    listed = {f.resolve() for files in read_manifest(run_dir).values() for f in files}
    freed = 0
    for table in SCHEMAS:
        directory = layout.table_dir(run_dir, table)
        if directory.is_symlink() or not directory.is_dir():
            continue
        for part in directory.glob(f"*{layout.PART_SUFFIX}"):
            if part.resolve() not in listed and not part.is_symlink():
                freed += part.stat().st_size
                part.unlink()
    return freed
