"""What a closed, unsealed run already holds, as a writer reopening it for appending needs to know: the parts
each table's manifest lists (with their row counts, from the Parquet footers), the counts the writer checks
ids against, the episodes begun and not ended, the first free episode id, and the program and vocabulary
rows (small tables), so that a new engine's program and vocabulary can be checked against them.

Read only while holding the run's writer lock (nobody else writes it), through the manifest's checked
paths (tracelab.store.parts.read_manifest: plain names inside the run, no links)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from tracelab.store.parts import manifest_flushes, read_manifest
from tracelab.store.schema import SCHEMAS

PROGRAM_TABLES = ("rules", "clauses", "facts", "policies")
VOCABULARY_TABLES = {"nodes": "node", "labels": "label", "atoms": "atom"}  # table -> its id column


@dataclass
class StoredRun:
    parts: dict[str, list[tuple[str, int]]]  # table -> (file name in parts/<table>/, rows), manifest order
    flushes: int
    small_tables: dict[str, pa.Table]        # the program's and the vocabulary's tables, ordered by id
    groundings: int
    changes: int
    open_episodes: set[int]
    next_free_episode: int                   # one past the highest episode id the run names

    def rows(self, table: str) -> int:
        return sum(n for _, n in self.parts[table])


def _read(files: list[Path], table: str, columns: list[str] | None = None) -> pa.Table:
    schema = SCHEMAS[table]
    if columns is not None:
        schema = pa.schema([schema.field(c) for c in columns])
    tables = [pq.read_table(f, columns=columns, schema=schema) for f in files]
    return pa.concat_tables(tables) if tables else schema.empty_table()


def stored_run(run_dir: Path) -> StoredRun:
    """The state of the run at `run_dir` as its manifest lists it."""
    files = read_manifest(run_dir)
    parts = {t: [(f.name, pq.ParquetFile(f).metadata.num_rows) for f in fs] for t, fs in files.items()}
    small = {t: _read(files[t], t) for t in PROGRAM_TABLES}
    for table, key in VOCABULARY_TABLES.items():
        small[table] = _read(files[table], table).sort_by(key)
    begun = _read(files["episode_begin"], "episode_begin", ["episode"]).column("episode").to_pylist()
    ended = _read(files["episode_end"], "episode_end", ["episode"]).column("episode").to_pylist()
    return StoredRun(parts=parts, flushes=manifest_flushes(run_dir), small_tables=small,
                     groundings=sum(n for _, n in parts["groundings"]),
                     changes=sum(n for _, n in parts["changes"]),
                     open_episodes=set(begun) - set(ended),
                     next_free_episode=max([*begun, *ended], default=-1) + 1)
