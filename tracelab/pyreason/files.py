"""What PyReason's rule and fact files share: UTF-8 text, CSV rows with an optional exact header, booleans
written as PyReason accepts them, and JSON lists of objects located by line and column."""
from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, TypeVar

from tracelab.engine.errors import RuleSyntaxError
from tracelab.engine.program import SourceLoc


class PyReasonFileError(RuleSyntaxError, ValueError):
    """A bad row of a PyReason rule or fact file: located as any rule text error, and a ValueError as
    PyReason's loaders raise (its tests/api_tests match their messages' words, kept here)."""


# How a loader treats a bad row: None raises (PyReason's raise_errors=True); a function is given the
# error and the loader goes on (raise_errors=False: PyReason warns, skips a row it cannot parse and gives
# a bad option its default value)
OnError = Callable[[PyReasonFileError], None] | None
T = TypeVar("T")


def file_error(e: RuleSyntaxError, prefix: str = "") -> PyReasonFileError:
    return PyReasonFileError(prefix + e.message, e.file, e.line, e.column, e.source_line)


def or_default(parse: Callable[[], T], default: T, on_error: OnError) -> T:
    """A row's option (a time, a boolean): `parse()`, or with on_error its default after reporting."""
    try:
        return parse()
    except RuleSyntaxError as e:
        if on_error is None:
            raise file_error(e) from None
        on_error(file_error(e))
        return default


def each_row(items: Iterable[T], parse: Callable[[T], Any], on_error: OnError, what: str) -> list[Any]:
    """parse(item) for each item; a row that fails raises `Failed to parse <what> - ...` (PyReason's
    words), or with on_error is reported and skipped."""
    out = []
    for item in items:
        try:
            out.append(parse(item))
        except PyReasonFileError as e:
            if on_error is None:
                raise
            on_error(e)
        except RuleSyntaxError as e:
            err = file_error(e, f"Failed to parse {what} - ")
            if on_error is None:
                raise err from None
            on_error(err)
    return out


def parse_bool(value: str, what: str, loc: SourceLoc, line: str) -> bool:
    """PyReason's booleans in its CSV files: true/1/yes/t/y, false/0/no/f/n, or empty (false)."""
    v = value.strip().lower()
    if v in ("true", "1", "yes", "t", "y"):
        return True
    if v in ("false", "0", "no", "f", "n", ""):
        return False
    raise PyReasonFileError(f"Invalid {what} value '{value}' (a boolean: true/false, 1/0, yes/no)", loc.file,
                            loc.line, loc.column, line)


@dataclass
class CsvRow:
    """One row of a PyReason CSV file: its fields, and where each field starts."""
    file: str
    line: int
    fields: list[str]
    columns: list[int]
    source: str  # the line's text

    def field(self, i: int) -> str:
        return self.fields[i] if i < len(self.fields) else ""

    def at(self, i: int) -> SourceLoc:
        return SourceLoc(self.file, self.line, self.columns[i] if i < len(self.columns) else 1)


def csv_rows(text: str, file: str, header: list[str]) -> list[CsvRow]:
    """The rows of a PyReason CSV file, without its optional exact header and without blank rows."""
    lines = text.splitlines()
    out: list[CsvRow] = []
    reader = csv.reader(io.StringIO(text))
    first_line = 1
    for row in reader:
        line = first_line
        first_line = reader.line_num + 1
        if not row or not any(f.strip() for f in row):
            continue
        if not out and [f.strip() for f in row] == header:
            continue
        src = lines[line - 1] if line - 1 < len(lines) else ""
        cols, pos = [], 0
        for f in row:
            k = src.find(f, pos) if f else -1
            cols.append(k + 1 if k >= 0 else pos + 1)
            pos = k + len(f) if k >= 0 else pos
        out.append(CsvRow(file, line, row, cols, src))
    return out


class JsonFinder:
    """Locations in a JSON text: the json module gives none for values, so a rule is located by finding
    its rule_text string after the previous one."""

    def __init__(self, text: str, file: str) -> None:
        self.text, self.file, self.pos = text, file, 0
        self.lines = text.splitlines()

    def _loc(self, k: int) -> SourceLoc:
        line = self.text.count("\n", 0, k) + 1
        return SourceLoc(self.file, line, k - (self.text.rfind("\n", 0, k) + 1) + 1)

    def find(self, s: str) -> SourceLoc:
        enc = json.dumps(s)[1:-1]
        k = self.text.find(enc, self.pos)
        if k < 0:  # written with other escapes: fall back to the next object
            return self.next_object()
        self.pos = k + len(enc)
        return self._loc(k)

    def next_object(self) -> SourceLoc:
        k = self.text.find("{", self.pos)
        return self._loc(max(k, 0))

    def line(self, n: int) -> str | None:
        return self.lines[n - 1] if 0 < n <= len(self.lines) else None

    def error(self, loc: SourceLoc, msg: str) -> PyReasonFileError:
        return PyReasonFileError(msg, loc.file, loc.line, loc.column, self.line(loc.line))




def json_items(text: str, file: str, text_key: str, what: str) -> Iterator[tuple[int, dict, SourceLoc, JsonFinder]]:
    """The objects of a JSON list, each located at its `text_key` string (rule_text / fact_text)."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise PyReasonFileError(f"Invalid JSON format in file {file}: {e.msg}", file, e.lineno, e.colno) from None
    except RecursionError:  # json recurses per level: 100,000 nested lists exhaust the stack
        raise PyReasonFileError(f"JSON nested too deeply for a PyReason {what} file", file, 1, 1) from None
    if not isinstance(data, list):
        raise PyReasonFileError(f"JSON file must contain an array of {what} objects, got {type(data).__name__}",
                                file, 1, 1)
    finder = JsonFinder(text, file)
    for i, obj in enumerate(data):
        has_text = isinstance(obj, dict) and isinstance(obj.get(text_key), str) and obj[text_key].strip()
        yield i, obj, finder.find(obj[text_key]) if has_text else finder.next_object(), finder


def required_text(i: int, obj: object, key: str, loc: SourceLoc, finder: JsonFinder) -> str:
    """An item's rule_text / fact_text, or PyReason's error for an item without one."""
    if not isinstance(obj, dict):
        raise PyReasonFileError(f"Item {i}: Expected object, got {type(obj).__name__}", loc.file, loc.line,
                                loc.column, finder.line(loc.line))
    text = obj.get(key)
    if not isinstance(text, str) or not text.strip():
        raise PyReasonFileError(f"Item {i}: Missing required '{key}'", loc.file, loc.line, loc.column,
                                finder.line(loc.line))
    return text
