"""The on-disk cache of compiled program kernels (docs/engine-api.md, "The compiled kernel").

One folder per key under the cache root: the generated module (`kernel.py`), numba's cache files for it
(`__pycache__/`, written by `cache=True` on the first call) and `ready.json`, written once a process has
compiled and run the kernel. The key is a hash of what determines the generated source (the program's
folded values, the whole of engine/kernel.py and of codegen.py) and of the cache's format and the
versions of tracelab, numba, llvmlite, numpy, Python and the CPU architecture: an upgrade or an edit of
any of them makes a new key, never a stale kernel. Old keys are never read again; deleting the root is
always safe.

Threat model. Whoever can write into this user's own private folders can run code as the user anyway, so
the protection against other people is the folders: the root is created 0700 (made 0700 when found looser)
and not used at all when another uid owns it; an entry that another uid owns (or a symbolic link) is
ignored and this user's kernel is built in `<key>.uid<N>` beside it. The digests below are not a defence
against that access (they live in the entry): they catch edited, half-written and malformed entries.

What is checked before anything of an entry runs or is loaded (under the entry's lock):
- kernel.py is never imported: the module is executed from the text the generator makes for the key, and
  the file must equal that text (numba hashes the file for its cache stamp; tracebacks read it). So neither
  the file nor a Python bytecode cache of it (`__pycache__/kernel.*.pyc`) is ever run.
- numba's cache files (the `.nbi` index and `.nbc` data of each function: pickles, so loading one runs
  code) live where numba's locator puts them, the entry's `__pycache__/` (under $NUMBA_CACHE_DIR when it
  is set); they are verified there rather than moved. ready.json records the sha256 of each one; before
  numba's first call the folder must hold exactly those files with those digests. An entry that does not
  match has its files removed (EntryRejected) and is compiled again; one without ready.json never had its
  numba files checked, so they are removed before compiling.
"""
from __future__ import annotations

import fcntl
import functools
import hashlib
import json
import os
import platform
import shutil
import stat
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from types import ModuleType

from .codegen import GENERATOR_VERSION, Specialisation, fingerprint, generate
from .safe_files import MIB, FileRefused, create_new, open_regular, read_json

CACHE_ENV = "TRACELAB_CACHE_DIR"
# part of every key: bump when what an entry holds or how it is checked changes, so that a tracelab of
# another format never reads (or writes a bytecode file into) this one's entries. 2: ready.json digests
CACHE_FORMAT = 2
READY_CAP = MIB  # ready.json: versions and one digest per numba file, a few KB
_LOADED: dict[Path, ModuleType] = {}  # one module object per entry folder and process
_HELD: dict[Path, int] = {}           # entry locks this process holds: how deep (the lock is re-entrant)


class CacheRefused(OSError):
    """The compile cache cannot be used (its root or an entry belongs to another user, or cannot be
    created): the compiled kernel is not used. The message is one line naming the folder."""


class EntryRejected(Exception):
    """A cache entry that did not match what it must hold (the generated source, the digests of numba's
    files): its files were removed, so the next compile rebuilds it. The message names the file and why."""


def cache_root() -> Path:
    """$TRACELAB_CACHE_DIR, else $XDG_CACHE_HOME/tracelab, else ~/.cache/tracelab; compiled kernels
    live in its `compiled/` folder."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]) / "compiled"
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "tracelab" / "compiled"


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "none"


@functools.cache
def versions() -> dict[str, str]:
    """Everything besides the source that decides whether a compiled kernel can be reused (looked up
    once per process: each metadata.version reads the installed packages' metadata)."""
    return {"generator": str(GENERATOR_VERSION), "cache_format": str(CACHE_FORMAT),
            "tracelab": _version("tracelab"), "numba": _version("numba"),
            "llvmlite": _version("llvmlite"), "numpy": _version("numpy"), "python": sys.version.split()[0],
            "machine": platform.machine()}


def cache_key(fingerprint: str) -> str:
    """The key of a kernel: its fingerprint (codegen.fingerprint) and the library versions."""
    h = hashlib.sha256(fingerprint.encode())
    h.update(json.dumps(versions(), sort_keys=True).encode())
    return h.hexdigest()[:24]


def _write_new(path: Path, data: bytes) -> None:
    with os.fdopen(create_new(path), "wb") as f:
        f.write(data)


def _not_yours(st: os.stat_result, path: Path) -> str | None:
    """Why a folder is not this user's private folder to use, or None."""
    if not stat.S_ISDIR(st.st_mode):
        return f"{path} is not a folder"
    if st.st_uid != os.geteuid():
        return f"{path} is owned by uid {st.st_uid}, not by you (uid {os.geteuid()})"
    return None


def private_folder(path: Path, *, follow_symlinks: bool) -> None:
    """Create `path` private to this user (0700), or check that the existing one is this user's folder
    (made 0700 if it was looser). The root may be reached through a link the user made (~/.cache on
    another disk); an entry may not."""
    try:
        path.mkdir(mode=0o700, parents=follow_symlinks, exist_ok=True)
        st = os.stat(path) if follow_symlinks else os.lstat(path)
        if why := _not_yours(st, path):
            raise CacheRefused(f"{why}; the compile cache is not used there")
        if stat.S_IMODE(st.st_mode) & 0o077:
            os.chmod(path, 0o700)
    except CacheRefused:
        raise
    except OSError as e:
        raise CacheRefused(f"cannot use {e.filename or path} for the compile cache: {e.strerror or e}") from None


def _entry_folder(root: Path, key: str) -> tuple[Path, str | None]:
    """The entry's folder, and a note when the usual one is not this user's and is ignored."""
    usual = root / key
    try:
        st = os.lstat(usual)
    except OSError:
        return usual, None
    if stat.S_ISLNK(st.st_mode):
        why: str | None = f"{usual} is a symbolic link"
    else:
        why = _not_yours(st, usual)
    if why is None:
        return usual, None
    instead = root / f"{key}.uid{os.geteuid()}"
    return instead, f"{why}: ignored; this kernel is cached in {instead} instead"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open_regular(path, follow_symlinks=False) as f:
        while chunk := f.read(MIB):
            h.update(chunk)
    return h.hexdigest()


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def _execute(name: str, path: Path, source: str) -> ModuleType:
    """The module made by running `source` (under the file name `path`, which numba's cache and
    tracebacks use); the file itself is not read."""
    module = ModuleType(name)
    module.__file__ = str(path)
    sys.modules[name] = module  # numba's cache rebuilds functions through their module
    exec(compile(source, str(path), "exec"), module.__dict__)
    return module


def _numba_folder(module: ModuleType) -> Path | None:
    """Where numba caches the module's functions (its locator's choice; all share one source file)."""
    cache = getattr(module.step_worlds, "_cache", None)
    path = getattr(cache, "cache_path", None)
    return Path(path) if path else None


class CacheEntry:
    """The cache folder of one program's kernel (its source is generated only when loaded)."""

    def __init__(self, spec: Specialisation, root: Path | None = None) -> None:
        self.spec = spec
        self.key = cache_key(fingerprint(spec))
        self.root = root or cache_root()
        self.dir, self.ignored = _entry_folder(self.root, self.key)  # `ignored`: why the usual folder is not used
        self.module_path = self.dir / "kernel.py"
        self.ready_path = self.dir / "ready.json"
        self.numba_dir: Path | None = None  # known once loaded

    @property
    def ready(self) -> bool:
        """True when some process compiled this kernel and recorded numba's files (load() checks them)."""
        try:
            return stat.S_ISREG(os.lstat(self.ready_path).st_mode)
        except OSError:
            return False

    def prepare(self) -> None:
        """The cache root and this entry's folder, private to this user (CacheRefused when they cannot be)."""
        private_folder(self.root, follow_symlinks=True)
        private_folder(self.dir, follow_symlinks=False)

    @contextmanager
    def locked(self) -> Iterator[None]:
        """Hold the entry's lock (an flock on `compile.lock`, re-entrant within a process): compiles,
        checks and removals happen under it, so no process removes files that another is writing."""
        if self.dir in _HELD:
            _HELD[self.dir] += 1
            try:
                yield
            finally:
                _HELD[self.dir] -= 1
            return
        self.prepare()
        fd = os.open(self.dir / "compile.lock", os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)  # released when the descriptor closes (or the process dies)
            _HELD[self.dir] = 1
            yield
        finally:
            _HELD.pop(self.dir, None)
            os.close(fd)

    def load(self) -> ModuleType:
        """The generated module, checked against the entry (written on first use; numba compiles it on the
        first step, or loads its cached machine code once checked). EntryRejected when the entry did not
        match (its files are then removed); CacheRefused when the cache cannot be used."""
        if self.dir in _LOADED:
            return _LOADED[self.dir]
        source = generate(self.spec)
        with self.locked():
            if why := self._kernel_mismatch(source):
                self.clear()
                raise EntryRejected(why)
            if not self.module_path.exists():
                self._write_kernel(source)
            module = _execute(f"tracelab_compiled_{self.key}", self.module_path, source)
            self.numba_dir = _numba_folder(module)
            if not self.ready:
                self._forget_numba_files()
            elif why := self._numba_mismatch():
                self.clear()
                raise EntryRejected(why)
        _LOADED[self.dir] = module
        return module

    @contextmanager
    def compiling(self) -> Iterator[None]:
        """Around the first call of a loaded kernel that is not ready: under the lock, numba's files are
        either those ready.json records (another process compiled the kernel meanwhile) or none."""
        with self.locked():
            if not self.ready or self._numba_mismatch():
                self._forget_numba_files()
            yield

    def _write_kernel(self, source: str) -> None:
        # write, then link to the final name: a reader never sees a half-written file, and an existing one
        # is never replaced (numba's cache is stamped with the file)
        tmp = self.dir / f"kernel.{os.getpid()}.{time.monotonic_ns()}.tmp"
        _write_new(tmp, source.encode())
        try:
            os.link(tmp, self.module_path)
        except FileExistsError:
            pass
        finally:
            tmp.unlink()

    def _kernel_mismatch(self, source: str) -> str | None:
        """Why kernel.py is not the generated source (None when it is, or is not written yet)."""
        try:
            with open_regular(self.module_path, follow_symlinks=False) as f:
                on_disk = f.read(len(source.encode()) + 1)
        except FileNotFoundError:
            return None
        except (FileRefused, OSError) as e:
            return f"{self.module_path}: cannot be read ({e})"
        if on_disk != source.encode():
            return f"{self.module_path} differs from the source generated for this kernel"
        return None

    def _numba_files(self) -> list[Path]:
        if self.numba_dir is None or not self.numba_dir.is_dir():
            return []
        return sorted(self.numba_dir.iterdir())

    def _numba_mismatch(self) -> str | None:
        """Why numba's files are not exactly those ready.json records (None when they are)."""
        try:
            recorded = read_json(self.ready_path, READY_CAP, what="compile cache record", follow_symlinks=False)
        except (FileRefused, OSError) as e:
            return f"{self.ready_path} cannot be read ({e})"
        digests = recorded.get("numba_files") if isinstance(recorded, dict) else None
        if not isinstance(digests, dict) or not digests:
            return f"{self.ready_path} records no digests of numba's files (an older tracelab wrote it?)"
        found = {p.name: p for p in self._numba_files()}
        if extra := sorted(set(found) - set(digests)):
            return f"{found[extra[0]]} is not a file this kernel's compile wrote"
        if missing := sorted(set(digests) - set(found)):
            return f"{self.numba_dir}/{missing[0]} is missing"
        for name, path in found.items():
            try:
                digest = _sha256(path)
            except (FileRefused, OSError) as e:
                return f"{path} cannot be read ({e})"
            if digest != digests[name]:
                return f"{path} does not match the digest recorded in {self.ready_path.name}"
        return None

    def _forget_numba_files(self) -> None:
        """Remove numba's files and the record of them (whatever sits at ready.json's name)."""
        _remove(self.ready_path)
        for path in self._numba_files():
            _remove(path)

    def clear(self) -> None:
        """Remove what a compile writes (kernel.py, ready.json, numba's files once the module was run and
        their folder is known; else the next load removes them, unused without ready.json): the next
        compile rebuilds the entry."""
        self._forget_numba_files()
        _remove(self.module_path)
        _LOADED.pop(self.dir, None)

    def mark_ready(self, compile_s: float | None) -> None:
        """Record that the kernel compiled, with the digest of each of numba's files (under the lock,
        right after the first call wrote them)."""
        if self.ready:
            return
        files = {p.name: _sha256(p) for p in self._numba_files()}
        if not files:  # numba cached nothing (an unwritable folder): nothing to load next time
            return
        info = {"versions": versions(), "compiled_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "first_call_s": compile_s, "numba_files": files}
        tmp = self.dir / f"ready.{os.getpid()}.{time.monotonic_ns()}.tmp"
        _write_new(tmp, json.dumps(info, indent=1).encode())
        os.replace(tmp, self.ready_path)
