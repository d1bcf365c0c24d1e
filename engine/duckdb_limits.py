"""The limits of a DuckDB connection that reads files from strangers: memory, spill files and threads.
The run sandbox (tracelab/store/sandbox.py) and the fact-table reader (engine/facttable.py) take them, so
a file never gets DuckDB's own default of 80% of the machine's memory per connection."""
from __future__ import annotations

import os
import shutil
import tempfile
from typing import NamedTuple

from tracelab.engine.grounding_limit import usable_memory
from tracelab.engine.safe_files import human_bytes, size_setting

GIB = 1 << 30
QUERY_MEMORY_ENV = "TRACELAB_QUERY_MEMORY"
# DuckDB's own default is 80% of the machine, per connection: a `trace --limit 5` on a 400M-row live run
# once took 18.5 GB. By default a connection gets a quarter of the machine, at most 4 GiB...
MACHINE_FRACTION = 4
DEFAULT_CAP = 4 * GIB
# ... and may spill up to 4 times that to disk (at most half the free space there): a big sort or join
# still finishes, slower, instead of failing, and never fills the disk (DuckDB's default: 90% of it).
SPILL_FACTOR = 4
# one thread per GiB (DuckDB advises 1-4 GiB per thread for joins and aggregates; each thread holds its
# own buffers, so more threads than that fail sooner under the same limit)
BYTES_PER_THREAD = GIB


class SandboxSettingError(ValueError):
    """A setting of the sandbox given in the environment that cannot be used (one line, names it)."""


class QueryMemory(NamedTuple):
    """What one sandbox connection may use: bytes of memory and of spill files, and threads. (A NamedTuple,
    not a dataclass: ~1 ms less of every reading command's start.)"""
    memory: int
    spill: int
    threads: int
    source: str  # how the memory limit was chosen, for messages

    def duckdb_config(self) -> dict[str, object]:
        return {"memory_limit": f"{self.memory}B", "max_temp_directory_size": f"{self.spill}B",
                "threads": self.threads}


def query_memory() -> QueryMemory:
    """The limits of a sandbox connection: $TRACELAB_QUERY_MEMORY (a size: 8G, 500M) if set, else a
    quarter of this machine's memory (or its container's), at most 4 GiB."""
    given = size_setting(QUERY_MEMORY_ENV, SandboxSettingError)
    if given is not None:
        memory, source = given, f"set by {QUERY_MEMORY_ENV}"
    else:
        total = usable_memory()
        memory = min(total // MACHINE_FRACTION, DEFAULT_CAP)
        source = f"a quarter of this machine's {human_bytes(total)}, at most {human_bytes(DEFAULT_CAP)}"
    try:
        free = shutil.disk_usage(tempfile.gettempdir()).free
    except OSError:
        free = 0  # no temp folder: no spilling (tracelab/store/sandbox.py, _spill_directory)
    threads = max(1, min(os.cpu_count() or 1, memory // BYTES_PER_THREAD))
    return QueryMemory(memory, max(1, min(SPILL_FACTOR * memory, free // 2)), threads, source)


_GLOB_CHARACTERS = "*?["


def exact_file(path: str | os.PathLike[str]) -> str:
    """`path` as DuckDB's read_parquet/read_csv take it to name that one file: they expand `*`, `?` and
    `[..]` anywhere in a path (a run folder named `r*` once read the parts of every run beside it), so
    each such character is written as a one-character class (`[*]`), which matches only itself."""
    return "".join(f"[{c}]" if c in _GLOB_CHARACTERS else c for c in os.fspath(path))
