"""What PyReason's rule and fact files share: UTF-8 text, CSV rows with an optional exact header, booleans
written as PyReason accepts them, and JSON lists of objects located by line and column."""
from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterator
from dataclasses import dataclass

from tracelab.engine.errors import RuleSyntaxError
from tracelab.engine.program import SourceLoc


def parse_bool(value: str, what: str, loc: SourceLoc, line: str) -> bool:
    """PyReason's booleans in its CSV files: true/1/yes/t/y, false/0/no/f/n, or empty (false)."""
    v = value.strip().lower()
    if v in ("true", "1", "yes", "t", "y"):
        return True
    if v in ("false", "0", "no", "f", "n", ""):
        return False
    raise RuleSyntaxError(f"{what} '{value}' is not a boolean (true/false, 1/0, yes/no)", loc.file, loc.line,
                          loc.column, line)


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

    def error(self, loc: SourceLoc, msg: str) -> RuleSyntaxError:
        return RuleSyntaxError(msg, loc.file, loc.line, loc.column, self.line(loc.line))




def json_items(text: str, file: str, text_key: str, what: str) -> Iterator[tuple[int, dict, SourceLoc, JsonFinder]]:
    """The objects of a JSON list, each located at its `text_key` string (rule_text / fact_text)."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise RuleSyntaxError(f"not a JSON file: {e.msg}", file, e.lineno, e.colno) from None
    except RecursionError:  # json recurses per level: 100,000 nested lists exhaust the stack
        raise RuleSyntaxError(f"JSON nested too deeply for a PyReason {what} file", file, 1, 1) from None
    if not isinstance(data, list):
        raise RuleSyntaxError(f"a PyReason {what} file in JSON is a list of {what} objects", file, 1, 1)
    finder = JsonFinder(text, file)
    for i, obj in enumerate(data):
        if not isinstance(obj, dict) or not isinstance(obj.get(text_key), str):
            raise finder.error(finder.next_object(), f"item {i}: expected an object with a '{text_key}' string")
        yield i, obj, finder.find(obj[text_key]), finder
