"""The files a run's program was read from (a spec, its rule files, a reasoning's fact files), kept in the
run as the `sources` table: one row per file with its role, path, size, sha256 and text (and a text no
file holds: a PyReason program's translation).

The texts go in a part, not in meta.json: a rule file may be tens of MiB (engine.parser.RULE_FILE_CAP)
while every reader of meta.json refuses more than META_CAP. meta.json keeps each source's summary
(source_summaries: role, path, bytes, sha256), small whatever the files hold."""
from __future__ import annotations

import hashlib
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import pyarrow as pa

from tracelab.engine.parser import RULE_FILE_CAP
from tracelab.engine.safe_files import read_bytes
from tracelab.store.arrow_build import table_from_rows
from tracelab.store.schema import SCHEMAS


def read_sources(files: Iterable[tuple[str, str]]) -> list[dict[str, Any]]:
    """A `sources` row per (role, path): the file read once (bounded as a rule file is), its size and hash
    of the bytes read, its text (NULL unless UTF-8)."""
    rows = []
    for role, path in files:
        data = read_bytes(path, RULE_FILE_CAP, what="program file")
        try:
            text: str | None = data.decode("utf-8")
        except UnicodeDecodeError:
            text = None
        rows.append({"role": role, "path": str(path), "bytes": len(data),
                     "sha256": hashlib.sha256(data).hexdigest(), "text": text})
    return rows


def text_source(role: str, text: str) -> dict[str, Any]:
    """A `sources` row of a text no file holds (a PyReason program's tracelab translation): no path."""
    data = text.encode()
    return {"role": role, "path": None, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest(), "text": text}


def source_summaries(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """What meta.json records of each source: everything but its text."""
    return [{k: v for k, v in r.items() if k != "text"} for r in rows]


def sources_tables(rows: Sequence[Mapping[str, Any]]) -> list[pa.Table]:
    """The rows as `sources` tables, one per file (an Arrow string column holds at most 2 GiB)."""
    return [table_from_rows([r], SCHEMAS["sources"]) for r in rows]
