"""Run metadata: what command produced a run, with which config, rules, seed and versions, and when.

Stored as meta.json in the run directory (human-readable, rewritten atomically) and, in a sealed run, as
the one-row table raw.run."""
from __future__ import annotations

import datetime as _dt
import fcntl
import hashlib
import json
import os
import platform
import socket
import sys
import time
from dataclasses import asdict, dataclass, field
from importlib import metadata
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import tracelab
from tracelab.engine.safe_files import JSON_CAP, FileRefused, human_bytes, open_regular, read_json
from tracelab.store import layout
from tracelab.store.portable_paths import portable_config, portable_path
from tracelab.store.schema import BOARD_BEFORE_DECLARED, arrow_schema
from tracelab.validation import (INT64, Const, IsoTime, ListOf, MapOf, Nullable, OneOf, OptionalKey, check_file,
                                 utc_time)

if TYPE_CHECKING:
    import pyarrow as pa

# deferred: numpy (library_versions: a writer has loaded it, a reader of meta.json need not) and arrow_build
# (pyarrow, for raw.run's table): every reading command reads meta.json through this module

FORMAT = "tracelab-run/1"
STATUSES = ("running", "finished", "failed", "interrupted", "crashed")
# The most meta.json may hold: what its readers accept (read_meta) is what its writer may write, so a run
# never holds a meta.json that its own readers refuse. Big texts (a program's files) go in parts instead
# (tracelab.store.sources).
META_CAP = JSON_CAP


@dataclass
class RunMeta:
    """What the caller knows about a run; the writer fills in versions, times, pid and host."""
    command: str = ""
    config: dict[str, Any] = field(default_factory=dict)
    scenario: str | None = None
    rule_files: list[str] = field(default_factory=list)
    seed: int | None = None
    versions: dict[str, str] = field(default_factory=dict)
    # the board a viewer draws the run's episodes on (a game declares its own, e.g. "gridworld"); None
    # for a run without one, such as a reasoning run (`tracelab reason --run`)
    board: str | None = None


def now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="microseconds")


def file_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def library_versions() -> dict[str, str]:
    import numpy as np
    import pyarrow as pa
    return {"tracelab": tracelab.__version__, "python": platform.python_version(),
            "numpy": np.__version__, "duckdb": _duckdb_version(), "pyarrow": pa.__version__}


def _duckdb_version() -> str:
    """DuckDB's version without importing it (a process that only writes a run need not load DuckDB:
    docs/benchmarks/history.md, "Memory of long runs"): its installed distribution's version, which is the
    module's; the module's if it is loaded already or has no distribution record."""
    module = sys.modules.get("duckdb")
    if module is None:
        try:
            return metadata.version("duckdb")
        except metadata.PackageNotFoundError:
            import duckdb as module
    return module.__version__


def initial_meta(run_dir: Path, meta: RunMeta | dict[str, Any] | None) -> dict[str, Any]:
    """The meta.json document of a run being opened now by this process; the files it names by portable
    paths (tracelab.store.portable_paths), the program by its name alone (argv[0], where it is installed)."""
    if meta is None:
        meta = RunMeta()
    elif isinstance(meta, dict):
        unknown = set(meta) - set(RunMeta.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown run metadata field(s) {sorted(unknown)}; "
                             f"known: {sorted(RunMeta.__dataclass_fields__)}")
        meta = RunMeta(**meta)
    rule_files = []
    for p in meta.rule_files:
        if not Path(p).is_file():
            raise FileNotFoundError(f"rule file {str(p)!r} named in the run metadata does not exist")
        rule_files.append({"path": portable_path(str(p), run_dir), "sha256": file_sha256(p)})
    doc = asdict(meta)
    doc.update(format=FORMAT, run_id=run_dir.name, rule_files=rule_files, config=portable_config(meta.config, run_dir),
               versions={**library_versions(), **meta.versions}, started_at=now_iso(), ended_at=None,
               status="running", pid=os.getpid(), host=socket.gethostname(), argv=_argv(), sealed_at=None)
    return doc


def _argv() -> list[str]:
    return [os.path.basename(a) if i == 0 else a for i, a in enumerate(sys.argv)]


def reopened_meta(run_dir: Path, doc: dict[str, Any], changes: dict[str, Any]) -> dict[str, Any]:
    """meta.json of a closed run reopened now by this process for appending (TraceWriter.reopen): running
    again, with `changes` applied (checked as a read meta.json is; the paths they name portable)."""
    doc = {**doc, **portable_config(changes, run_dir), "status": "running", "ended_at": None, "pid": os.getpid(),
           "host": socket.gethostname(), "argv": _argv()}
    return check_file(doc, META_SCHEMA, Path(layout.META))


def meta_bytes(run_dir: Path, doc: dict[str, Any]) -> bytes:
    """meta.json's bytes; refused (FileRefused) past META_CAP."""
    data = json.dumps(doc, indent=2, sort_keys=True, default=str).encode()
    if len(data) > META_CAP:
        raise FileRefused(f"{layout.meta_path(run_dir)}: run metadata of {human_bytes(len(data))} is over "
                          f"the {human_bytes(META_CAP)} its readers accept; refused (a big text, such as "
                          f"a program's file, belongs in the run's parts)")
    return data


def write_meta(run_dir: Path, doc: dict[str, Any]) -> None:
    """meta.json, atomically; refused (FileRefused, nothing written) past META_CAP."""
    layout.replace_atomically(meta_bytes(run_dir, doc), layout.meta_path(run_dir))


# What each key of meta.json must hold (every key optional: runs of earlier versions lack some). Checked
# when the file is read: a run from elsewhere is refused with one line naming the key, instead of failing
# later in whatever code uses the value.
META_SCHEMA: dict[str, Any] = {key: OptionalKey(spec) for key, spec in {
    "format": Const(FORMAT),
    "run_id": str,
    "command": str,
    "config": {},
    "scenario": Nullable(str),
    "rule_files": ListOf({"path": str, "sha256": str}),
    "seed": Nullable(INT64),
    "versions": MapOf(str),
    "started_at": IsoTime(),
    "ended_at": Nullable(IsoTime()),
    "status": OneOf(*STATUSES),
    "pid": Nullable(INT64),
    "host": Nullable(str),
    "argv": ListOf(str),
    "sealed_at": Nullable(IsoTime()),
    # a resumed training's resumes into the same run (tracelab train --resume), oldest first
    "resumes": ListOf({}),
    "board": Nullable(str),  # the run's declared board (RunMeta.board)
}.items()}


def read_meta(run_dir: Path) -> dict[str, Any]:
    path = layout.meta_path(run_dir)
    try:
        doc = read_json(path, META_CAP, what="run's meta.json", follow_symlinks=False)
    except FileNotFoundError:
        raise FileNotFoundError(f"{str(run_dir)!r} is not a tracelab run: it has no {layout.META}") from None
    return check_file(doc, META_SCHEMA, path)


def open_writer_lock(run_dir: Path) -> IO[bytes]:
    """The run's writer.lock, created if missing, to take the lock on: a regular file of the run, never
    through a link (which would create a file wherever it points), never a FIFO."""
    return open_regular(layout.lock_path(run_dir), follow_symlinks=False, create=True)


def writer_holds_lock(run_dir: Path) -> bool:
    """Whether a process (a writer, or seal) holds the run's writer lock now. Probes with a shared lock
    taken and released at once on a read-only descriptor; never creates the lock file."""
    try:
        lock = open_regular(layout.lock_path(run_dir), follow_symlinks=False)
    except FileNotFoundError:
        return False
    with lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(lock, fcntl.LOCK_UN)
        return False


def take_writer_lock(run_dir: Path, lock: IO[bytes], doc: dict[str, Any], doing: str) -> None:
    """Take the run's writer lock or raise RuntimeError naming the writer. Retried for a moment: readers
    probe the lock (a shared lock held for microseconds) to tell a live run from a crashed one."""
    for attempt in range(10):
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            time.sleep(0.005 * (attempt + 1))
    raise RuntimeError(f"run {str(run_dir)!r} is still being written (pid {doc.get('pid')}); "
                       f"close its writer before {doing}")


def current_meta(run_dir: Path) -> dict[str, Any]:
    """meta.json with the run's status as of now: a run recorded as 'running' whose writer lock nobody
    holds lost its writer ('crashed')."""
    doc = read_meta(run_dir)
    if doc.get("status", "running") == "running" and not writer_holds_lock(run_dir):
        doc = read_meta(run_dir)  # the writer may have closed between the two looks
        if doc.get("status", "running") == "running":
            doc["status"] = "crashed"
    return doc


def _ts(value: str | None) -> _dt.datetime | None:
    return utc_time(value) if value else None


def meta_row(doc: dict[str, Any], status: str) -> dict[str, Any]:
    """raw.run's one row (schema.RUN_COLUMNS); config, rule files and versions as JSON text."""
    return {
        "run_id": doc.get("run_id"), "command": doc.get("command"), "scenario": doc.get("scenario"),
        "seed": doc.get("seed"), "status": status,
        "started_at": _ts(doc.get("started_at")), "ended_at": _ts(doc.get("ended_at")),
        "config": json.dumps(doc.get("config", {}), sort_keys=True),
        "rule_files": json.dumps(doc.get("rule_files", [])),
        "versions": json.dumps(doc.get("versions", {}), sort_keys=True),
        "pid": doc.get("pid"), "host": doc.get("host"), "board": doc.get("board", BOARD_BEFORE_DECLARED),
    }


def meta_table(doc: dict[str, Any], status: str) -> "pa.Table":
    """raw.run as an Arrow table of its one row (meta_row)."""
    from tracelab.store.arrow_build import table_from_rows
    return table_from_rows([meta_row(doc, status)], arrow_schema("run"))
