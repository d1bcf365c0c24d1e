"""A live run's Parquet parts and the manifest that says which of them make up the run.

Layout of parts/:
  <table>/00000042.parquet ...   immutable parts (temp name, then rename; a file never changes once named)
  manifest.json                  for every table, the parts that hold its rows now (replaced atomically)
Readers query exactly the files the manifest lists (each a plain file name of its table's folder, listed
once, a regular file: read_manifest checks them), never a directory listing: DuckDB lists a glob's
directory and then stats each entry, so a listing taken while parts were being merged could silently
drop rows (seen: a reader got only the big parts of a table, without the part they had just been merged
into). One manifest for all tables also gives a reader one consistent moment across tables.

A publication writes one new part per table with rows; then the writer replaces the manifest. When a
table holds `compact_files` small parts (fewer rows than part_rows and than MERGE_BELOW_ROWS), or small
parts of part_rows rows in all, they are merged into one new part (read one at a time) and leave the
table's list: a merge holds about part_rows rows, however long the run (merging 64 parts at a time held
millions); their files are deleted `grace_seconds` later, so a reader still holding the previous
manifest can finish its query. A crash before the manifest is replaced leaves parts nobody lists:
invisible and harmless (seal ignores them and removes parts/)."""
from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path
from collections.abc import Iterable
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from tracelab.engine.memory import BIG_WORK, release_freed_memory
from tracelab.engine.safe_files import check_regular, read_json
from tracelab.store import layout
from tracelab.store.arrow_build import empty_table
from tracelab.store.schema import ADDED_TABLES, DICTIONARY_COLUMNS, PART_OPTIONS, SCHEMAS
from tracelab.validation import Const, ExactKeys, IntRange, ListOf, Matches, OptionalKey, check_file

ROW_GROUP_ROWS = 131_072
# A part of at least this many rows (or of part_rows, if fewer) is never merged: merging re-encodes every
# row, which took half the writer's CPU in a fast `tracelab play --run` (its parts of 50k-150k rows were
# merged in twos: docs/benchmarks/history.md, "Traced runs: the writer"), and such a part fills a quarter of a
# row group already. Smaller parts (a slow run's, flushed every second) are merged as before.
MERGE_BELOW_ROWS = 32_768
# A merge's row groups: a quarter of ROW_GROUP_ROWS, since a merge's rows are read from disk while the
# game goes on (a published part's rows are in memory already). A merge of ~250k change rows then held
# 7-13 MB at its peak, 22-25 MB with row groups of ROW_GROUP_ROWS (docs/benchmarks/history.md, "Memory of long
# runs"); its part is ~9% larger.
MERGE_ROW_GROUP_ROWS = 32_768
MANIFEST_FORMAT = "tracelab-parts/1"


class TableParts:
    """One table's parts: writes new ones, merges small ones, and knows which files hold the table."""

    def __init__(self, run_dir: Path, table: str, part_rows: int, compact_files: int = 64,
                 grace_seconds: float = 30.0, compression: str = "zstd",
                 existing: list[tuple[str, int]] | None = None) -> None:
        """`existing`: the parts (file name, rows) a reopened run's manifest lists, to continue from."""
        if compact_files < 2:
            raise ValueError(f"compact_files must be >= 2, got {compact_files}")
        self.table = table
        self.schema = SCHEMAS[table]
        self.root = layout.make_run_dirs(run_dir, layout.PARTS, table)
        self.part_rows = part_rows
        self.big_rows = min(part_rows, MERGE_BELOW_ROWS)  # parts this big are never merged
        self.compact_files = compact_files
        self.grace_seconds = grace_seconds
        self.compression = compression
        self._next_file = 0
        self._small: list[str] = []   # listed parts with fewer than big_rows rows, oldest first
        self._small_rows = 0          # and their rows
        self._big: list[str] = []
        self._retired: list[tuple[float, list[str]]] = []
        self.rows_published = 0
        self.files_written = 0
        self.compactions = 0
        self.seconds = 0.0  # spent writing this table's parts (tracelab bench reason-store reads it)
        if existing is not None:  # a reopened run: new parts are numbered after every file of the folder
            self._next_file = next_part_number(self.root)
            for name, rows in existing:
                self._add(name, rows)
                self.rows_published += rows
            return
        # An empty first part, so that every table has a file that carries its schema.
        self._add(*self._write([empty_table(self.schema)]))

    @property
    def files(self) -> list[str]:
        """The table's parts now, as paths relative to parts/ (the manifest's form)."""
        return [f"{self.table}/{name}" for name in (*self._big, *self._small)]

    def _write(self, tables: Iterable[pa.Table], group_rows: int | None = None) -> tuple[str, int]:
        """A new part of the rows of `tables`, in order, in row groups of `group_rows` (ROW_GROUP_ROWS
        unless given; the last one smaller), taken one table at a time: memory for a row group and a
        table, however many rows the part gets (a compaction merges millions). Returns its name and rows."""
        group_rows = group_rows or ROW_GROUP_ROWS
        name = layout.part_name(self._next_file)
        self._next_file += 1
        rows = 0
        with layout.new_file(self.root / name) as f, pq.ParquetWriter(
                f, self.schema, compression=self.compression,
                use_dictionary=DICTIONARY_COLUMNS.get(self.table, True), **PART_OPTIONS.get(self.table, {})) as out:
            held: list[pa.Table] = []  # rows short of a full row group
            for table in tables:
                held.append(table)
                rows += table.num_rows
                waiting = sum(t.num_rows for t in held)
                if waiting >= group_rows:
                    joined = pa.concat_tables(held)
                    full = waiting - waiting % group_rows
                    out.write_table(joined.slice(0, full), row_group_size=group_rows)
                    held = [joined.slice(full)]
            if rows == 0 or any(t.num_rows for t in held):
                out.write_table(pa.concat_tables(held) if held else empty_table(self.schema),
                                row_group_size=group_rows)
        self.files_written += 1
        return name, rows

    def _add(self, name: str, rows: int) -> None:
        if rows >= self.big_rows:
            self._big.append(name)
        else:
            self._small.append(name)
            self._small_rows += rows

    def publish(self, tables: list[pa.Table]) -> int:
        """Write these rows as a new part (merging small parts when there are enough) and list it; readers
        see it once the writer replaces the manifest. Returns how many rows were written."""
        n = sum(t.num_rows for t in tables)
        if n == 0:
            return 0
        t0 = time.perf_counter()
        self._add(*self._write(tables))
        self.rows_published += n
        if len(self._small) >= self.compact_files or (len(self._small) > 1 and self._small_rows >= self.part_rows):
            self._compact()
        self._drop_retired()
        self.seconds += time.perf_counter() - t0
        return n

    def _compact(self) -> None:
        """Merge the small parts into one, read one at a time (memory stays flat however many rows)."""
        merged = self._write((_read_part(self.root / name) for name in self._small), MERGE_ROW_GROUP_ROWS)
        self._retired.append((time.monotonic(), self._small))
        self._small, self._small_rows = [], 0
        self._add(*merged)
        self.compactions += 1
        # what the reads and the writer freed, back to the system: after every merge, however few its rows
        # (64 parts of a few thousand steps rows each left ~10 MB resident until the next big merge)
        release_freed_memory(BIG_WORK)

    def _drop_retired(self) -> None:
        now = time.monotonic()
        while self._retired and now - self._retired[0][0] >= self.grace_seconds:
            for name in self._retired.pop(0)[1]:
                (self.root / name).unlink(missing_ok=True)


def _read_part(path: Path) -> pa.Table:
    """One part's rows, for a merge: through ParquetFile, not pq.read_table, whose dataset layer loads
    Arrow's dataset, Acero and Substrait libraries (~15 MB resident that a writing process kept for good
    after its first merge: docs/benchmarks/history.md, "Memory of long runs"); single-threaded and without
    pre-buffering (pyarrow's IO threads' buffers)."""
    with pq.ParquetFile(path, pre_buffer=False) as f:
        return f.read(use_threads=False)


def write_manifest(run_dir: Path, parts: dict[str, TableParts], flushes: int) -> None:
    """Replace parts/manifest.json with the tables' current parts: the moment readers see."""
    write_manifest_lists(run_dir, {name: p.files for name, p in parts.items()}, flushes)


def write_manifest_lists(run_dir: Path, files: dict[str, list[str]], flushes: int) -> None:
    """Replace parts/manifest.json: for every table, its parts as paths relative to parts/."""
    doc = {"format": MANIFEST_FORMAT, "flushes": flushes, "tables": files}
    layout.replace_atomically(json.dumps(doc).encode(), layout.manifest_path(run_dir))


def manifest_flushes(run_dir: Path) -> int:
    """How many flushes the manifest records."""
    return read_manifest_doc(run_dir)["flushes"]


def next_part_number(directory: Path) -> int:
    """One past the highest numbered part in a table's folder (listed or not: never reuse a name)."""
    stems = [name[: -len(layout.PART_SUFFIX)] for name in os.listdir(directory)
             if name.endswith(layout.PART_SUFFIX)]
    return max((int(s) for s in stems if s.isdigit()), default=-1) + 1


def write_empty_part(run_dir: Path, table: str) -> str:
    """A new part with no rows (it carries the table's schema), named after the table's highest part;
    returns its manifest entry."""
    directory = layout.make_run_dirs(run_dir, layout.PARTS, table)
    final = directory / layout.part_name(next_part_number(directory))
    with layout.new_file(final) as f:
        pq.write_table(empty_table(SCHEMAS[table]), f)
    return f"{table}/{final.name}"


def _part_entry(table: str) -> Matches:
    """A manifest entry of `table`: `<table>/<file name>` (how parts are written: `rules/00000003.parquet`).
    A plain name, so DuckDB reads that one file: no folder, no glob character (DuckDB expands globs in a
    file list), no '..'."""
    return Matches(re.escape(table) + "/[A-Za-z0-9_][A-Za-z0-9_.-]*" + re.escape(layout.PART_SUFFIX),
                   f"a plain file name in the run's parts/{table}/ directory, like "
                   f"'{table}/{layout.part_name(3)}' (no folders, globs or '..')")


# parts/manifest.json: its format, `flushes` a count, and for exactly the store's tables a list of plain
# part names of the table's folder, each listed once (a run written before a table was added,
# schema.ADDED_TABLES, lists none for it).
MANIFEST_SCHEMA: dict[str, Any] = {
    "format": Const(MANIFEST_FORMAT),
    "flushes": OptionalKey(IntRange(0, (1 << 63) - 1, "a count (an integer >= 0)")),
    "tables": ExactKeys({table: OptionalKey(ListOf(_part_entry(table), unique=True)) if table in ADDED_TABLES
                         else ListOf(_part_entry(table), unique=True) for table in SCHEMAS}),
}


def read_manifest_doc(run_dir: Path) -> dict[str, Any]:
    """parts/manifest.json, checked against MANIFEST_SCHEMA (FileRefused naming the key)."""
    path = layout.manifest_path(run_dir)
    try:
        doc = read_json(path, what="parts manifest", follow_symlinks=False)
    except FileNotFoundError:
        raise FileNotFoundError(f"{str(run_dir)!r} has no {layout.PARTS}/{layout.MANIFEST}: not a "
                                "tracelab run directory, or one whose writer died while creating it") from None
    check_file(doc, MANIFEST_SCHEMA, path)
    doc.setdefault("flushes", 0)
    return doc


def read_manifest(run_dir: Path) -> dict[str, list[Path]]:
    """For every table, the absolute paths of the parts that hold its rows now (read_manifest_doc's
    checks; each part, if it exists, a regular file reached through no link: a FIFO would hang DuckDB)."""
    doc = read_manifest_doc(run_dir)
    root = Path(run_dir).resolve()
    out: dict[str, list[Path]] = {}
    for table in SCHEMAS:
        out[table] = []
        for entry in doc["tables"].get(table, []):  # none: a table added after the run was written
            part = layout.run_path(root, layout.PARTS, table, entry.partition("/")[2])
            try:
                check_regular(part, follow_symlinks=False)
            except FileNotFoundError:
                pass  # `check` reports a missing part as damaged; a query says which file it lacks
            out[table].append(part)
    return out


def remove_unlisted(run_dir: Path) -> int:
    """Delete the parts the manifest does not list: merged parts a killed writer had not yet removed and
    parts written after its last manifest (only while holding the writer lock: a live writer's retired
    parts are still being read). Returns how many bytes were freed."""
    listed = {table: {p.name for p in files} for table, files in read_manifest(run_dir).items()}
    freed = 0
    for table in SCHEMAS:
        directory = layout.table_dir(run_dir, table)
        if not directory.is_dir():
            continue
        for entry in os.scandir(directory):
            if entry.name.endswith(layout.PART_SUFFIX) and entry.name not in listed[table] \
                    and entry.is_file(follow_symlinks=False):
                freed += entry.stat(follow_symlinks=False).st_size
                os.unlink(entry.path)
    return freed
