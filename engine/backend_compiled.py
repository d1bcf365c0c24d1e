"""The compiled backend: the counting kernel's state and semantics, stepped by a kernel generated for
this one program (codegen.py) and cached on disk (compile_cache.py).

The state layout is the counting backend's, so everything but the step (growing, snapshots, restores,
recounts) is inherited and runs kernel.py's functions; only `step_worlds` comes from the generated module.
"""
from __future__ import annotations

import dataclasses
import time
from types import ModuleType

import numpy as np

from .backend_api import EngineTables
from .backend_counting import CountingState
from .codegen import GenerationError, Specialisation
from .compile_cache import CacheEntry, CacheRefused, EntryRejected
from .program import Fact, Literal, Program, Rule
from .notices import library_logger

# the fields of the program objects this backend knows; a program that sets any other field (a language
# feature newer than the generator) runs on the interpreter. %closed, %edge_heads, {set_static} and
# {infer_edges} live in tables the generated kernel reads as kernel.py does (clause flags, the groundings,
# rule_i's RULE_SET_STATIC column), so they need no rewriting.
_KNOWN_FIELDS = {Program: {"rules", "facts", "mode", "timesteps", "inconsistency", "edge_heads", "closed", "files",
                           "warnings"},
                 Rule: {"name", "head", "body", "delay", "immediate", "mode", "loc", "text", "set_static",
                        "infer_edges"},
                 Literal: {"pred", "args", "lower", "upper", "negated", "loc"},
                 Fact: {"name", "literal", "start", "end", "static", "loc", "text"}}


def _unknown_fields(obj: object) -> list[str]:
    """Fields of a program object this backend does not know, set to something other than their default."""
    known = next((v for cls, v in _KNOWN_FIELDS.items() if isinstance(obj, cls)), set())
    out = []
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        if f.name in known:
            continue
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else dataclasses.MISSING)
        if getattr(obj, f.name) != default:
            out.append(f.name)
    return out


def unsupported(program: Program) -> str | None:
    """Why the compiled backend cannot take `program` (a language feature it does not know), or None."""
    if bad := _unknown_fields(program):
        return f"the program uses {', '.join(bad)}"
    for r in program.rules:
        for obj in (r, r.head, *r.body):
            if bad := _unknown_fields(obj):
                return f"{r.described} uses {', '.join(bad)}"
    for f in program.facts:
        for obj in (f, f.literal):
            if bad := _unknown_fields(obj):
                return f"{f.described} uses {', '.join(bad)}"
    return None


def cache_entry(eng: EngineTables) -> CacheEntry:
    """The cache entry of the kernel specialised to eng's program."""
    return CacheEntry(Specialisation.of(eng._cfg, eng._rule_i, eng._rule_f))


_AFTER_REMOVAL = {"compile": "it is compiled again now (about a minute)",
                  "build": "it is compiled again in the background",
                  "skip": "this run uses the counting kernel (`tracelab compile` builds it again)"}
_SAID: set[str] = set()  # notices said once per process
# notices go to the `tracelab` loggers (warnings: a kernel not used); the CLI shows them on stderr
log = library_logger(__name__)


def compiled_backend(eng: EngineTables, program: Program, uncached: str
                     ) -> tuple["CompiledState | None", str | None, CacheEntry | None]:
    """The compiled backend for eng, or None and why not (a notice), and the cache entry still to build.
    `uncached` says what to do when the cache lacks this program's kernel: "skip" (kernel="auto": None,
    silently), "compile" (the backend, whose first step compiles) or "build" (None and the entry, for a
    background compile). A program the backend cannot take, or a cache that cannot be used, gets a
    one-line warning on this module's logger and None (the caller runs the counting kernel), unless
    `uncached` is "skip". A cache entry that fails its checks (compile_cache.py) is removed with a
    one-line warning, then treated as not cached."""
    why = unsupported(program)
    if why is None:
        try:
            return _from_cache(eng, cache_entry(eng), uncached)
        except (GenerationError, CacheRefused, EntryRejected) as e:
            why = str(e)
    if uncached == "skip":
        return None, None, None
    notice = f"kernel 'compiled' not used: {why}; running on the counting kernel"
    log.warning(notice)
    return None, notice, None


def _from_cache(eng: EngineTables, entry: CacheEntry, uncached: str
                ) -> tuple["CompiledState | None", str | None, CacheEntry | None]:
    if entry.ignored and entry.ignored not in _SAID:  # another user's entry: said once, not used
        _SAID.add(entry.ignored)
        log.warning(f"kernel cache: {entry.ignored}")
    notice = None
    if entry.ready or uncached == "compile":
        try:
            return CompiledState(eng, entry), None, None
        except EntryRejected as e:  # its files are removed: the entry is now simply not cached
            notice = (f"kernel 'compiled': the cached kernel failed its check: {e}; removed it, "
                      f"{_AFTER_REMOVAL[uncached]}")
            log.warning(notice)
        if uncached == "compile":
            return CompiledState(eng, entry), None, None
    if uncached == "build":
        return None, None, entry
    return None, notice, None


class CompiledState(CountingState):
    name = "compiled"

    def __init__(self, eng: EngineTables, entry: CacheEntry) -> None:
        super().__init__(eng)
        self.entry = entry
        self.module: ModuleType = entry.load()
        self.step_kernel = self.module.step_worlds
        self._ready = entry.ready

    @classmethod
    def taking_over(cls, state: CountingState, entry: CacheEntry) -> "CompiledState":
        """The compiled backend going on from a counting backend's state between two steps: the same
        arrays (no copy), stepped from now on by the kernel generated from the counting kernel's own
        source, so the run goes on exactly as it would have on the counting kernel."""
        new = cls.__new__(cls)
        new.__dict__.update(state.__dict__)
        new.entry = entry
        new.module = entry.load()
        new.step_kernel = new.module.step_worlds
        new._ready = entry.ready
        return new

    def step(self, ext_ptr: np.ndarray, ext_i: np.ndarray, ext_f: np.ndarray) -> int:
        if self._ready:
            return super().step(ext_ptr, ext_i, ext_f)
        with self.entry.compiling():  # numba's files checked (or none) before its first call reads them
            t0 = time.perf_counter()  # the first call compiles (or loads numba's cache) and runs one step
            status = super().step(ext_ptr, ext_i, ext_f)
            self.entry.mark_ready(round(time.perf_counter() - t0, 3))
        self._ready = True
        return status
