"""Where a run's files live, and the one way to reach them (`run_path`).

A run directory holds:
  meta.json                 run metadata (written at open and at close, each time to a temp name + rename)
  writer.lock               flock-ed by the writing process (and by `seal`) while they work
  parts/manifest.json       which parts make up each table now (replaced atomically at every flush)
  parts/<table>/NNNNNNNN.parquet
                            immutable Parquet parts (written to a temp name, then renamed); see
                            tracelab.store.parts for the manifest and compaction
  quarantine/<table>/       damaged parts `tracelab check --repair` took out of the manifest
  run.duckdb                the sealed form (everything in one DuckDB file); once it exists it is the run
A sealed run may also be a lone .duckdb file anywhere.

Runs come from strangers (a bug report's attachment, a colleague's copy), so every reader and writer of
the store reaches a run's files through `run_path`: plain names only, and no symbolic link anywhere
below the run directory (a `quarantine` linked to a home folder once let `check --repair` overwrite that
home's .bashrc). With plain names and no links, no path it returns can resolve outside the run. The run
directory itself may be a link: the user named it.

Files the store creates are created new under a temp name (O_CREAT|O_EXCL|O_NOFOLLOW: never through a
link or into a file planted at that name) and renamed into place (a rename replaces a link, never writes
through it); folders it creates are checked after mkdir."""
from __future__ import annotations

import os
import shutil
import stat
from contextlib import AbstractContextManager
from pathlib import Path
from typing import IO

from tracelab.engine.safe_files import FileRefused, replacing

META = "meta.json"
LOCK = "writer.lock"
PARTS = "parts"
SEALED = "run.duckdb"
MANIFEST = "manifest.json"
QUARANTINE = "quarantine"
PART_SUFFIX = ".parquet"
TMP_MARK = ".tmp-"


def run_path(run_dir: Path, *names: str) -> Path:
    """run_dir/names..., refused (FileRefused) if a name is not a plain file name, or if a component below
    run_dir that exists is a symbolic link (or, above the last, not a directory). Components that do not
    exist yet are fine: whoever creates them does so with make_run_dirs / new_file."""
    for name in names:
        if name in ("", ".", "..") or "/" in name or "\0" in name:
            raise FileRefused(f"{Path(run_dir, *names)}: {name!r} is not a plain file name; refused")
    path = Path(run_dir)
    for i, name in enumerate(names):
        path = path / name
        try:
            mode = os.lstat(path).st_mode
        except FileNotFoundError:
            return path.joinpath(*names[i + 1:])
        if stat.S_ISLNK(mode):
            raise refused_link(path)
        if i < len(names) - 1 and not stat.S_ISDIR(mode):
            raise FileRefused(f"{path}: is not a directory; refused")
    return path


def refused_link(path: Path) -> FileRefused:
    return FileRefused(f"{path}: is a symbolic link (to {os.readlink(path)!r}); refused: a link inside a "
                       "run could lead outside the run")


def make_run_dirs(run_dir: Path, *names: str) -> Path:
    """Create run_dir/names... like `mkdir -p`, each folder checked after mkdir: a directory of the
    run, not a link (run_path) and not a file."""
    for i in range(1, len(names) + 1):
        path = run_path(run_dir, *names[:i])
        try:
            os.mkdir(path)
        except FileExistsError:
            pass
        if not stat.S_ISDIR(os.lstat(path).st_mode):
            raise FileRefused(f"{path}: is not a directory; refused")
    return run_path(run_dir, *names)


def meta_path(run_dir: Path) -> Path:
    return run_path(run_dir, META)


def lock_path(run_dir: Path) -> Path:
    return run_path(run_dir, LOCK)


def sealed_path(run_dir: Path) -> Path:
    return run_path(run_dir, SEALED)


def parts_dir(run_dir: Path) -> Path:
    return run_path(run_dir, PARTS)


def table_dir(run_dir: Path, table: str) -> Path:
    return run_path(run_dir, PARTS, table)


def part_name(number: int) -> str:
    return f"{number:08d}{PART_SUFFIX}"


def manifest_path(run_dir: Path) -> Path:
    return run_path(run_dir, PARTS, MANIFEST)


def tmp_name(final: Path) -> Path:
    return final.with_name(f".{final.name}{TMP_MARK}{os.getpid()}")


def is_temp(name: str) -> bool:
    return name.startswith(".") and TMP_MARK in name


def remove_stale_temps(run_dir: Path) -> int:
    """Delete the temp files (and a failed seal's temp folder) a killed writer or a failed seal left
    behind (only while holding the writer lock: a live writer's temp files are in use); returns how
    many. Only in the run's own folders: run_path refuses a parts/ that is a link."""
    parts = run_path(run_dir, PARTS)
    folders = [Path(run_dir)]
    if parts.is_dir():
        folders += [parts, *(parts / e.name for e in os.scandir(parts) if e.is_dir(follow_symlinks=False))]
    n = 0
    for folder in folders:
        for entry in os.scandir(folder):
            if is_temp(entry.name):
                if entry.is_dir(follow_symlinks=False):
                    shutil.rmtree(entry.path)
                else:
                    os.unlink(entry.path)  # a link is removed itself, never its target
                n += 1
    return n


def new_file(final: Path) -> AbstractContextManager[IO[bytes]]:
    """A file to write that becomes `final` when the block ends (`final` comes from run_path): created new
    under the store's temp name beside it, then renamed (engine.safe_files.replacing)."""
    return replacing(final, 0o644, tmp_name(final))


def replace_atomically(data: bytes, final: Path) -> None:
    """Write `data` to a temp name beside `final`, then rename it over `final`."""
    with new_file(final) as f:
        f.write(data)


def check_new_run_dir(run_dir: Path, what: str = "--run") -> None:
    """A run goes into a new or empty directory: never into a file, an existing run, or a folder of
    other things (they would be mixed with the run's files). `what` names the option in the message."""
    from tracelab.errors import UserError
    if run_dir.exists() and not run_dir.is_dir():
        raise UserError(f"{what} {run_dir}: this is a file, not a directory; give a new run directory")
    if meta_path(run_dir).exists():
        raise UserError(f"{what} {run_dir} already holds a run; give a new run directory")
    if run_dir.is_dir():
        others = sorted(p.name for p in run_dir.iterdir())
        if others:
            shown = ", ".join(others[:5]) + (", ..." if len(others) > 5 else "")
            raise UserError(f"{what} {run_dir} holds other files ({shown}); give a new or empty directory")
