"""The on-disk cache of compiled program kernels (docs/engine-api.md, "The compiled kernel").

One directory per key under the cache root: the generated module (`kernel.py`), numba's cache files
beside it (`__pycache__/`, written by `cache=True` on the first call) and `ready.json`, written once a
process has compiled and run the kernel. The key is a hash of what determines the generated source
(the program's folded values, the whole of engine/kernel.py and of codegen.py) and of the versions of
tracelab, numba, llvmlite, numpy, Python and the CPU architecture: an upgrade or an edit of any of them
makes a new key, never a stale kernel. Old keys are never read again; deleting the root is always safe.
"""
from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import os
import platform
import sys
import time
from importlib import metadata
from pathlib import Path
from types import ModuleType

from .codegen import GENERATOR_VERSION, Specialisation, fingerprint, generate

CACHE_ENV = "TRACELAB_CACHE_DIR"
_LOADED: dict[str, ModuleType] = {}  # one module object per key and process


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
    return {"generator": str(GENERATOR_VERSION), "tracelab": _version("tracelab"), "numba": _version("numba"),
            "llvmlite": _version("llvmlite"), "numpy": _version("numpy"), "python": sys.version.split()[0],
            "machine": platform.machine()}


def cache_key(fingerprint: str) -> str:
    """The key of a kernel: its fingerprint (codegen.fingerprint) and the library versions."""
    h = hashlib.sha256(fingerprint.encode())
    h.update(json.dumps(versions(), sort_keys=True).encode())
    return h.hexdigest()[:24]


class CacheEntry:
    """The cache directory of one program's kernel (its source is generated only when loaded)."""

    def __init__(self, spec: Specialisation, root: Path | None = None) -> None:
        self.spec = spec
        self.key = cache_key(fingerprint(spec))
        self.dir = (root or cache_root()) / self.key
        self.module_path = self.dir / "kernel.py"
        self.ready_path = self.dir / "ready.json"

    @property
    def ready(self) -> bool:
        """True when some process compiled this kernel and numba's cache holds it."""
        return self.ready_path.exists() and (self.dir / "__pycache__").is_dir()

    def load(self) -> ModuleType:
        """The generated module (written on first use; numba compiles it on the first step, or loads
        its cached machine code when the cache holds it)."""
        if self.key in _LOADED:
            return _LOADED[self.key]
        self.dir.mkdir(parents=True, exist_ok=True)
        if not self.module_path.exists():
            # write, then link to the final name unless another process got there first: a reader never
            # imports a half-written file, and an existing one is never replaced (numba's cache is keyed
            # on the file's time stamp: replacing it by equal text would make the cache stale)
            tmp = self.dir / f"kernel.{os.getpid()}.{time.monotonic_ns()}.tmp"
            tmp.write_text(generate(self.spec))
            try:
                os.link(tmp, self.module_path)
            except FileExistsError:
                pass
            finally:
                tmp.unlink()
        name = f"tracelab_compiled_{self.key}"
        spec = importlib.util.spec_from_file_location(name, self.module_path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # numba's cache locates functions through their module
        spec.loader.exec_module(module)
        _LOADED[self.key] = module
        return module

    def mark_ready(self, compile_s: float | None) -> None:
        if self.ready_path.exists():
            return
        info = {"versions": versions(), "compiled_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "first_call_s": compile_s}
        tmp = self.dir / f"ready.{os.getpid()}.tmp"
        tmp.write_text(json.dumps(info, indent=1))
        os.replace(tmp, self.ready_path)
