"""One table's Parquet parts in a live run directory.

Files never change once they have their final name (DuckDB may open a file more than once per query, so
a file replaced in place can be read torn). Layout of parts/<table>/:
  g000003/00000042.parquet ...   a generation: the complete set of the table's parts
  live -> g000003                the generation readers scan (their glob is parts/<table>/live/*.parquet)
A flush writes a new part into the live generation (temp name, then rename). When the live generation
holds `compact_files` small parts (< part_rows rows), they are merged into one new part in a new
generation, which also hard-links every other part, and `live` is switched to it by renaming a symlink
over it: one atomic step, so a reader's listing is always one complete generation, and every name means
the same bytes in every generation. A reader that listed the old generation just before the switch and
opens a merged-away part just after it gets "file not found": retry (tracelab.store.reader.retrying).
Old generations are deleted after `grace_seconds`; a crash mid-compaction leaves the old one live."""
from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from tracelab.store import layout
from tracelab.store.schema import SCHEMAS

ROW_GROUP_ROWS = 131_072


class TableParts:
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
        self.gen = 0
        self._next_file = 0
        self._small: list[str] = []   # parts of the live generation with fewer than part_rows rows
        self._big: list[str] = []
        self._retired: list[tuple[float, Path]] = []
        self.rows_published = 0
        self.files_written = 0
        self.compactions = 0
        self._gen_dir(0).mkdir(parents=True, exist_ok=True)
        # An empty first part, so that readers' globs match from the start and carry the schema.
        self._add(self._write(self._gen_dir(0), self.schema.empty_table()), 0)
        self._point_live_at(0)

    def _gen_dir(self, gen: int) -> Path:
        return self.root / layout.gen_name(gen)

    def _write(self, directory: Path, table: pa.Table) -> str:
        name = layout.part_name(self._next_file)
        self._next_file += 1
        final = directory / name
        tmp = layout.tmp_name(final)
        pq.write_table(table, tmp, compression=self.compression, row_group_size=ROW_GROUP_ROWS)
        os.replace(tmp, final)
        self.files_written += 1
        return name

    def _add(self, name: str, rows: int) -> None:
        (self._big if rows >= self.part_rows else self._small).append(name)

    def _point_live_at(self, gen: int) -> None:
        link = self.root / layout.LIVE
        tmp = layout.tmp_name(link)
        os.symlink(layout.gen_name(gen), tmp)
        os.replace(tmp, link)

    def publish(self, tables: list[pa.Table]) -> int:
        """Make these rows visible to readers (one new part); returns how many rows were published."""
        n = sum(t.num_rows for t in tables)
        if n == 0:
            return 0
        table = pa.concat_tables(tables) if len(tables) > 1 else tables[0]
        self._add(self._write(self._gen_dir(self.gen), table), n)
        self.rows_published += n
        if len(self._small) >= self.compact_files:
            self._compact()
        self._drop_retired()
        return n

    def _compact(self) -> None:
        old, new = self._gen_dir(self.gen), self._gen_dir(self.gen + 1)
        if new.exists():  # left by a crash of an earlier writer process: never live, safe to remove
            shutil.rmtree(new)
        new.mkdir()
        merged = pa.concat_tables([pq.read_table(old / name, schema=self.schema) for name in self._small])
        merged_name = self._write(new, merged)
        for name in self._big:
            os.link(old / name, new / name)
        self._point_live_at(self.gen + 1)
        self.gen += 1
        self._small = []
        self._add(merged_name, merged.num_rows)
        self._retired.append((time.monotonic(), old))
        self.compactions += 1

    def _drop_retired(self) -> None:
        now = time.monotonic()
        while self._retired and now - self._retired[0][0] >= self.grace_seconds:
            shutil.rmtree(self._retired.pop(0)[1], ignore_errors=True)
