"""Where a run's files live.

A run directory holds:
  meta.json                 run metadata (written at open and at close, each time to a temp name + rename)
  writer.lock               flock-ed by the writing process (and by `seal`) while they work
  parts/manifest.json       which parts make up each table now (replaced atomically at every flush)
  parts/<table>/NNNNNNNN.parquet
                            immutable Parquet parts (written to a temp name, then renamed); see
                            tracelab.store.parts for the manifest and compaction
  run.duckdb                the sealed form (everything in one DuckDB file); once it exists it is the run
A sealed run may also be a lone .duckdb file anywhere."""
from __future__ import annotations

import os
from pathlib import Path

META = "meta.json"
LOCK = "writer.lock"
PARTS = "parts"
SEALED = "run.duckdb"
MANIFEST = "manifest.json"
PART_SUFFIX = ".parquet"
TMP_MARK = ".tmp-"


def meta_path(run_dir: Path) -> Path:
    return run_dir / META


def lock_path(run_dir: Path) -> Path:
    return run_dir / LOCK


def sealed_path(run_dir: Path) -> Path:
    return run_dir / SEALED


def table_dir(run_dir: Path, table: str) -> Path:
    return run_dir / PARTS / table


def part_name(number: int) -> str:
    return f"{number:08d}{PART_SUFFIX}"


def manifest_path(run_dir: Path) -> Path:
    return run_dir / PARTS / MANIFEST


def tmp_name(final: Path) -> Path:
    return final.with_name(f".{final.name}{TMP_MARK}{os.getpid()}")


def remove_stale_temps(run_dir: Path) -> int:
    """Delete the temp files a killed writer or a failed seal left behind (only while holding the writer
    lock: a live writer's temp files are in use); returns how many."""
    n = 0
    for d in (run_dir, run_dir / PARTS, *(run_dir / PARTS).glob("*/")):
        if d.is_dir() and not d.is_symlink():
            for p in d.glob(f".*{TMP_MARK}*"):
                p.unlink(missing_ok=True)
                n += 1
    return n


def replace_atomically(data: bytes, final: Path) -> None:
    """Write `data` to a temp name beside `final`, then rename it over `final`."""
    tmp = tmp_name(final)
    with open(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, final)
