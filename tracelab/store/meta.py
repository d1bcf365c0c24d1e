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
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import IO, Any

import pyarrow as pa

from tracelab.engine.safe_files import FileRefused, open_regular, read_json
from tracelab.store import layout

FORMAT = "tracelab-run/1"
STATUSES = ("running", "finished", "failed", "interrupted", "crashed")


@dataclass
class RunMeta:
    """What the caller knows about a run; the writer fills in versions, times, pid and host."""
    command: str = ""
    config: dict[str, Any] = field(default_factory=dict)
    scenario: str | None = None
    rule_files: list[str] = field(default_factory=list)
    seed: int | None = None
    versions: dict[str, str] = field(default_factory=dict)


def now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="microseconds")


def file_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def library_versions() -> dict[str, str]:
    import duckdb
    import numpy
    import pyarrow

    import tracelab
    return {"tracelab": tracelab.__version__, "python": platform.python_version(),
            "numpy": numpy.__version__, "duckdb": duckdb.__version__, "pyarrow": pyarrow.__version__}


def initial_meta(run_dir: Path, meta: RunMeta | dict[str, Any] | None) -> dict[str, Any]:
    """The meta.json document of a run being opened now by this process."""
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
        rule_files.append({"path": str(p), "sha256": file_sha256(p)})
    doc = asdict(meta)
    doc.update(format=FORMAT, run_id=run_dir.name, rule_files=rule_files,
               versions={**library_versions(), **meta.versions}, started_at=now_iso(), ended_at=None,
               status="running", pid=os.getpid(), host=socket.gethostname(), argv=list(sys.argv),
               sealed_at=None)
    return doc


def reopened_meta(doc: dict[str, Any], changes: dict[str, Any]) -> dict[str, Any]:
    """meta.json of a closed run reopened now by this process for appending (TraceWriter.reopen): running
    again, with `changes` applied (checked as a read meta.json is)."""
    doc = {**doc, **changes, "status": "running", "ended_at": None, "pid": os.getpid(),
           "host": socket.gethostname(), "argv": list(sys.argv)}
    return check_meta(doc, Path(layout.META))


def write_meta(run_dir: Path, doc: dict[str, Any]) -> None:
    data = json.dumps(doc, indent=2, sort_keys=True, default=str).encode()
    layout.replace_atomically(data, layout.meta_path(run_dir))


def _int64(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and -(1 << 63) <= v < (1 << 63)


def _time(v: Any) -> bool:
    if not isinstance(v, str) or not v:
        return False
    try:
        _ts(v)
    except (ValueError, OverflowError):
        return False
    return True


def _text(v: Any) -> bool:
    return isinstance(v, str)


def _texts(v: Any) -> bool:
    return isinstance(v, list) and all(isinstance(x, str) for x in v)


def _rule_files(v: Any) -> bool:
    return isinstance(v, list) and all(
        isinstance(f, dict) and isinstance(f.get("path"), str) and isinstance(f.get("sha256"), str) for f in v)


def _nullable(check: Callable[[Any], bool]) -> Callable[[Any], bool]:
    return lambda v: v is None or check(v)


# What each field of meta.json must hold (a field may be absent: runs of earlier versions lack some).
# Checked when the file is read: a run from elsewhere is refused with one line naming the key, instead
# of failing later in whatever code uses the value.
META_FIELDS: dict[str, tuple[Callable[[Any], bool], str]] = {
    "format": (lambda v: v == FORMAT, repr(FORMAT)),
    "run_id": (_text, "a string"),
    "command": (_text, "a string"),
    "config": (lambda v: isinstance(v, dict), "an object"),
    "scenario": (_nullable(_text), "a string or null"),
    "rule_files": (_rule_files, 'a list of {"path": string, "sha256": string} objects'),
    "seed": (_nullable(_int64), "a 64-bit integer or null"),
    "versions": (lambda v: isinstance(v, dict) and all(isinstance(x, str) for x in v.values()),
                 "an object of strings"),
    "started_at": (_time, "an ISO 8601 time"),
    "ended_at": (_nullable(_time), "an ISO 8601 time or null"),
    "status": (lambda v: v in STATUSES, "one of " + ", ".join(STATUSES)),
    "pid": (_nullable(_int64), "a 64-bit integer or null"),
    "host": (_nullable(_text), "a string or null"),
    "argv": (_texts, "a list of strings"),
    "sealed_at": (_nullable(_time), "an ISO 8601 time or null"),
    # a resumed training's resumes into the same run (tracelab train --resume), oldest first
    "resumes": (lambda v: isinstance(v, list) and all(isinstance(r, dict) for r in v), "a list of objects"),
}


def shown(value: Any, width: int = 40) -> str:
    """A JSON value for an error message, cut to `width` characters."""
    text = json.dumps(value, default=str)
    return text if len(text) <= width else text[: width - 3] + "..."


def check_meta(doc: Any, path: Path) -> dict[str, Any]:
    """meta.json's document, checked against META_FIELDS (FileRefused naming the file and key)."""
    if not isinstance(doc, dict):
        raise FileRefused(f"{path}: expected a JSON object, got {shown(doc)}")
    for key, (ok, expected) in META_FIELDS.items():
        if key in doc and not ok(doc[key]):
            raise FileRefused(f"{path}: key {key!r}: expected {expected}, got {shown(doc[key])}")
    return doc


def read_meta(run_dir: Path) -> dict[str, Any]:
    path = layout.meta_path(run_dir)
    try:
        doc = read_json(path, what="run's meta.json", follow_symlinks=False)
    except FileNotFoundError:
        raise FileNotFoundError(f"{str(run_dir)!r} is not a tracelab run: it has no {layout.META}") from None
    return check_meta(doc, path)


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
    if not value:
        return None
    return _dt.datetime.fromisoformat(value).astimezone(_dt.timezone.utc).replace(tzinfo=None)


def meta_table(doc: dict[str, Any], status: str) -> pa.Table:
    """raw.run: one row; config, rule files and versions as JSON text."""
    row = {
        "run_id": doc.get("run_id"), "command": doc.get("command"), "scenario": doc.get("scenario"),
        "seed": doc.get("seed"), "status": status,
        "started_at": _ts(doc.get("started_at")), "ended_at": _ts(doc.get("ended_at")),
        "config": json.dumps(doc.get("config", {}), sort_keys=True),
        "rule_files": json.dumps(doc.get("rule_files", [])),
        "versions": json.dumps(doc.get("versions", {}), sort_keys=True),
        "pid": doc.get("pid"), "host": doc.get("host"),
    }
    ts = pa.timestamp("us")  # UTC
    schema = pa.schema([("run_id", pa.string()), ("command", pa.string()), ("scenario", pa.string()),
                        ("seed", pa.int64()), ("status", pa.string()), ("started_at", ts),
                        ("ended_at", ts), ("config", pa.string()), ("rule_files", pa.string()),
                        ("versions", pa.string()), ("pid", pa.int64()), ("host", pa.string())])
    return pa.Table.from_pylist([row], schema=schema)
