"""Which sealed run files this user's tracelab has already checked (sealed_catalog.check_sealed_catalog),
so that reading the same file again skips the costly half of the check: DuckDB's list of every function
(thousands of built-ins, ~30-50 ms of CPU) and of every other catalog entry, on every command.

A file is known by its identity: device, inode, size, modification and status-change times (st_ctime:
no user can set it; any write, rename or chmod moves it). A checked file's identity is recorded as a
file named by its hash (with the checker's version: a tracelab that checks more checks again), holding
what the check found that its reader needs again (a sealed run's stored columns), in
$TRACELAB_CACHE_DIR/checked-runs, else in this user's runtime folder
($XDG_RUNTIME_DIR/tracelab-checked-runs), else in the temp folder (tracelab-checked-runs-UID): never in
the home folder (a reading command writes nothing there), and gone at reboot. The folder must be private
to this user (0700, owned by them, not a link); any other is not used, and whoever can write into this
user's private folders can run code as the user anyway (as for the compile cache, engine/compile_cache.py).
A record's text is read at most NOTE_CAP bytes, and its reader takes from it only what it checks again
(sealed_catalog: column names of its own schema). A file changed within RACY_S of its check could keep its
times (they tick every few milliseconds), so such a file is not recorded: it is checked each time until
it has been left alone that long. What is still checked every time: raw.run's one row and the
write-ahead log."""
from __future__ import annotations

import hashlib
import os
import stat
import tempfile
import time
from pathlib import Path

CACHE_ENV = "TRACELAB_CACHE_DIR"   # the compile cache's root too (engine/compile_cache.py)
FOLDER = "checked-runs"
RACY_S = 2.0
NOTE_CAP = 64 * 1024   # a record's text: a sealed run's column names take ~3 KB


def records_folder() -> Path:
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]) / FOLDER
    if os.environ.get("XDG_RUNTIME_DIR"):
        return Path(os.environ["XDG_RUNTIME_DIR"]) / f"tracelab-{FOLDER}"
    return Path(tempfile.gettempdir()) / f"tracelab-{FOLDER}-{os.geteuid()}"


def file_identity(path: Path) -> os.stat_result | None:
    try:
        return os.stat(path)
    except OSError:
        return None


def same_file(a: os.stat_result | None, b: os.stat_result | None) -> bool:
    return a is not None and b is not None and _key_fields(a) == _key_fields(b)


def _key_fields(st: os.stat_result) -> tuple[int, ...]:
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


def _record(st: os.stat_result, checker: str) -> Path:
    key = hashlib.sha256(f"{checker}:{_key_fields(st)}".encode()).hexdigest()[:32]
    return records_folder() / key


def _private(folder: Path) -> bool:
    try:
        st = os.lstat(folder)
    except OSError:
        return False
    return stat.S_ISDIR(st.st_mode) and st.st_uid == os.geteuid() and not stat.S_IMODE(st.st_mode) & 0o077


def was_checked(st: os.stat_result | None, checker: str) -> bool:
    """Whether the file of identity `st` passed `checker` (a version of the check) before."""
    return checked_note(st, checker) is not None


def checked_note(st: os.stat_result | None, checker: str) -> str | None:
    """The text recorded with the file of identity `st` when it passed `checker` ("" for none), or None
    if it did not pass before (or its record cannot be read as this user's own regular file)."""
    if st is None or not _private(records_folder()):
        return None
    try:
        fd = os.open(_record(st, checker), os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        data = os.read(fd, NOTE_CAP + 1)
        return data.decode("utf-8", "replace") if len(data) <= NOTE_CAP else ""   # past the cap: not ours
    except OSError:
        return None
    finally:
        os.close(fd)


def record_checked(st: os.stat_result | None, checker: str, note: str = "") -> None:
    """Record that the file of identity `st` passed `checker`, with `note` (checked_note reads it back),
    unless it changed within RACY_S; a folder that cannot be made, or is not this user's alone, is left
    alone (the check runs every time)."""
    if st is None or max(st.st_mtime_ns, st.st_ctime_ns) / 1e9 > time.time() - RACY_S:
        return
    folder = records_folder()
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)   # $TRACELAB_CACHE_DIR's
        folder.mkdir(mode=0o700, exist_ok=True)
        if not _private(folder):
            return
        # written whole under a temporary name, then renamed: a reader never sees half a note
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".record-")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(note.encode()[:NOTE_CAP])
            os.replace(tmp, _record(st, checker))
        except OSError:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError:
        pass  # no record: the check runs again next time
