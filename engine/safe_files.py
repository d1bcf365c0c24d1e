"""Reading files that may come from a stranger (a run, a policy, a checkpoint, a rule file, a graph, a
cache entry): only regular files, never through a symbolic link where the caller says so, never more
bytes than a cap, and never a hang.

Why each guard:
- A FIFO, a socket or a device opened for reading blocks (a FIFO waits for a writer forever) or never
  ends (/dev/zero). Files are opened with O_NONBLOCK, so that opening a FIFO returns at once, and the
  open descriptor is checked with fstat: the check and the read are of the same file, whatever is
  renamed in between.
- A symbolic link can point anywhere; the store refuses them inside a run (`follow_symlinks=False`,
  O_NOFOLLOW), while a path the user typed may be a link they made.
- A size cap is checked while reading, not from stat, so a file that grows as it is read is bounded too.

This module sits in the lowest layer (the engine reads rule files and graphs) and imports nothing of
tracelab's; `tracelab.errors` reports its error as a one-line user error."""
from __future__ import annotations

import errno
import json
import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

MIB = 1 << 20
JSON_CAP = 8 * MIB  # run metadata, manifests, policy descriptions: a few KB to a few hundred KB in practice


class FileRefused(ValueError):
    """A file that tracelab will not read (not a regular file, a symbolic link, too big, malformed JSON).
    The message is one line and starts with the file's path."""


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISLNK, "a symbolic link")):
        if test(mode):
            return name
    return "not a regular file"


_BYTE_UNITS = {"": 1, "K": 1 << 10, "M": MIB, "G": 1 << 30, "T": 1 << 40}


def parse_byte_size(text: str) -> int:
    """A number of bytes: 2000000000, 500M, 8G, 1.5T (binary units; a trailing B or iB is allowed);
    ValueError naming the text otherwise."""
    s = text.strip().upper().removesuffix("IB").removesuffix("B")
    unit = s[-1:] if s[-1:] in _BYTE_UNITS else ""
    try:
        value = float(s[:len(s) - len(unit)]) * _BYTE_UNITS[unit]
    except ValueError:
        raise ValueError(f"expected a size such as 8G or 500M, got {text!r}") from None
    if not value >= 1 or value == float("inf"):
        raise ValueError(f"must be at least 1 byte, got {text!r}")
    return int(value)


def size_setting(variable: str, error: type[Exception]) -> int | None:
    """The size an environment variable such as $TRACELAB_PARSE_MEMORY sets (8G, 500M), or None when it
    is unset or blank; `error` (one line naming the variable and its value) when it is not a size."""
    given = os.environ.get(variable, "").strip()
    if not given:
        return None
    try:
        return parse_byte_size(given)
    except ValueError as e:
        raise error(f"{variable}={given!r}: {e}") from None


def human_bytes(n: int) -> str:
    for unit, size in (("GiB", 1 << 30), ("MiB", MIB), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} bytes"


def open_regular(path: str | os.PathLike[str], *, follow_symlinks: bool = True,
                 create: bool = False) -> IO[bytes]:
    """Open a regular file for reading in binary mode (`create`: for reading and writing, created if
    missing, as a lock file is); FileRefused for anything else (FileNotFoundError and PermissionError
    pass through as they are)."""
    flags = (os.O_RDWR | os.O_CREAT if create else os.O_RDONLY) | os.O_NONBLOCK | os.O_CLOEXEC \
        | (0 if follow_symlinks else os.O_NOFOLLOW)
    try:
        fd = os.open(path, flags, 0o644)
    except ValueError:  # a NUL byte, which no file name can hold (a path written in a stranger's file)
        raise FileRefused(f"{os.fspath(path)!r}: a file name cannot hold a NUL byte; refused") from None
    except OSError as e:
        if e.errno == errno.ELOOP and not follow_symlinks:
            raise FileRefused(f"{path}: is a symbolic link; refused") from None
        raise
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise FileRefused(f"{path}: is {_kind(mode)}, not a regular file; refused")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "r+b" if create else "rb")
    except BaseException:
        os.close(fd)
        raise


def check_regular(path: str | os.PathLike[str], *, follow_symlinks: bool = True) -> Path:
    """Refuse a path that is not a regular file before handing it to a library that opens it itself
    (DuckDB, pyarrow, torch); returns it as a Path."""
    open_regular(path, follow_symlinks=follow_symlinks).close()
    return Path(path)


def read_bytes(path: str | os.PathLike[str], max_bytes: int, *, what: str = "file",
               follow_symlinks: bool = True) -> bytes:
    """The whole file, refused past `max_bytes` (`what` names the kind of file in the message)."""
    too_big = FileRefused(f"{path}: larger than {human_bytes(max_bytes)}, the limit for a {what}; refused")
    with open_regular(path, follow_symlinks=follow_symlinks) as f:
        size = os.fstat(f.fileno()).st_size
        if size > max_bytes:  # refused before reading a (sparse) giant into memory
            raise too_big
        # read(n) allocates n bytes first: the file's size (and one more, to see it grow), not the cap
        chunks = [f.read(size + 1)]
        while chunks[-1] and sum(map(len, chunks)) <= max_bytes:  # a file that grows as it is read
            chunks.append(f.read(min(MIB, max_bytes + 1 - sum(map(len, chunks)))))
    data = b"".join(chunks)
    if len(data) > max_bytes:
        raise too_big
    return data


def read_text(path: str | os.PathLike[str], max_bytes: int, *, what: str = "file",
              follow_symlinks: bool = True) -> str:
    data = read_bytes(path, max_bytes, what=what, follow_symlinks=follow_symlinks)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise FileRefused(f"{path}: not UTF-8 text (byte 0x{data[e.start]:02x} at offset {e.start})") from None


def read_json(path: str | os.PathLike[str], max_bytes: int = JSON_CAP, *, what: str = "JSON file",
              follow_symlinks: bool = True) -> Any:
    """A JSON document, bounded in size; malformed or too deeply nested JSON is one located line."""
    text = read_text(path, max_bytes, what=what, follow_symlinks=follow_symlinks)
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise FileRefused(f"{path}:{e.lineno}:{e.colno}: not valid JSON: {e.msg}") from None
    except RecursionError:
        raise FileRefused(f"{path}: JSON nested too deeply; refused") from None


def path_inside(folder: str | os.PathLike[str], name: str) -> Path:
    """`name`, a path relative to `folder` that a file from a stranger wrote (a spec's rule file), resolved
    with every link followed and refused (FileRefused) unless it stays inside `folder` (itself resolved):
    a link beside or below the file may point anywhere, so the written path alone proves nothing. The
    caller opens the resolved path, which names no link."""
    if not isinstance(name, str) or not name or "\0" in name:
        raise FileRefused(f"{name!r}: expected a file name (no NUL byte)")
    parts = name.replace("\\", "/").split("/")
    if os.path.isabs(name) or ".." in parts:
        raise FileRefused(f"{name!r}: expected a path relative to the folder, inside it")
    root = os.path.realpath(folder)
    resolved = os.path.realpath(os.path.join(root, name))
    if os.path.commonpath([root, resolved]) != root:
        raise FileRefused(f"{name!r}: a link to a file outside the folder {root}; refused")
    return Path(resolved)


def create_new(path: str | os.PathLike[str], mode: int = 0o600) -> int:
    """A file descriptor, open for writing, of a file created now: never an existing file (O_EXCL) and
    never through a symbolic link (O_NOFOLLOW), whatever sits at `path`."""
    return os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, mode)


@contextmanager
def replacing(final: str | os.PathLike[str], mode: int = 0o644,
              tmp: str | os.PathLike[str] | None = None) -> Iterator[IO[bytes]]:
    """A file to write that replaces `final` when the block ends: written under a temp name beside it
    (default `.NAME.PID.tmp`; created new, so nothing planted at that name is written through), then
    renamed over `final` (a rename replaces the name, never writes through a link put there); removed if
    the block fails. A stale temp of a dead process with this pid is removed first (unlink removes a
    link, not its target)."""
    final = Path(final)
    tmp = Path(tmp) if tmp is not None else final.with_name(f".{final.name}.{os.getpid()}.tmp")
    tmp.unlink(missing_ok=True)
    fd = create_new(tmp, mode)
    try:
        with os.fdopen(fd, "wb") as f:
            yield f
        os.replace(tmp, final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
