"""The paths a run records of its files, made portable: a file of tracelab's rules/ is named
`rules/<path in it>`, a file in the run's own directory `{run}/<path in it>` (RUN), any other path as it was
given. A run copied to another machine (the sample runs of a clone) then names no directory of the machine
that made it, wherever that kept tracelab or the run. The file's content is kept by its hash (and text, in
the run's `sources` table), so the path is what the file was called, not where to read it again."""
from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tracelab import RULES_DIR

RUN = "{run}"  # the run's own directory, in a path it records
RULES = "rules"  # tracelab's rules/ (the repository's, or the installed package's)


def portable_path(path: str, run_dir: Path) -> str:
    """`path` as a run in `run_dir` records it: under RULES or RUN when the file is in one, else unchanged.
    A relative path is read from the working directory, as the command that named it read it."""
    if not path or "\n" in path:
        return path
    full = os.path.abspath(path)
    for root, name in ((os.path.abspath(run_dir), RUN), (str(RULES_DIR), RULES)):
        if full == root or full.startswith(root + os.sep):
            return name + full[len(root):].replace(os.sep, "/")
    return path


def portable_config(value: Any, run_dir: Path) -> Any:
    """A run's config (meta.json's, any JSON value) with every string that names a file of RULES or the run
    portable: an absolute path by where it points, a relative one only if it names a file that exists (a
    registered env id, `namespace/Name-v0`, is no path, wherever the command ran)."""
    if isinstance(value, Mapping):
        return {k: portable_config(v, run_dir) for k, v in value.items()}
    if isinstance(value, list):
        return [portable_config(v, run_dir) for v in value]
    if isinstance(value, str) and "/" in value and (os.path.isabs(value) or os.path.lexists(value)):
        return portable_path(value, run_dir)
    return value

