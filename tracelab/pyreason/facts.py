"""PyReason's facts: the fact text (`popular(Mary) : true`, `~p(a)`, `link(a,b):[0.5,1]`) with a name, a
start and an end time (both included) and a static flag, read from PyReason's CSV fact files
(`fact_text,name,start_time,end_time,static`, the header optional) or its JSON fact files (a list of
objects with those keys). Any other extension reads as the CSV format."""
from __future__ import annotations

import os
from dataclasses import dataclass

from tracelab.engine.parser import read_rule_file
from tracelab.engine.program import SourceLoc

from .files import (
    CsvRow,
    JsonFinder,
    OnError,
    PyReasonFileError,
    csv_rows,
    each_row,
    json_items,
    or_default,
    parse_bool,
    required_text,
)
from .text import PLiteral, Squeezed, parse_literal


@dataclass
class PFact:
    name: str
    literal: PLiteral
    start: int
    end: int
    static: bool
    loc: SourceLoc


def parse_fact(text: str, loc: SourceLoc, source_line: str | None = None) -> PLiteral:
    sq = Squeezed(text, loc, source_line)
    if not sq.s:
        raise sq.error(0, "empty fact")
    return parse_literal(sq, 0, len(sq.s), "fact")


def read_facts(path: str | os.PathLike[str], on_error: OnError = None) -> list[PFact]:
    """The facts of a PyReason fact file; a bad row raises (located), or with `on_error` is reported
    and skipped (a bad time or static flag: reported, and PyReason's default used)."""
    file = os.fspath(path)
    text = read_rule_file(file)
    if os.path.splitext(file)[1].lower() == ".json":
        return _facts_json(text, file, on_error)
    return _facts_csv(text, file, on_error)


def _time(value: object, what: str, loc: SourceLoc, line: str | None) -> int:
    v = "" if value is None else value
    if isinstance(v, int) and not isinstance(v, bool) and v >= 0:
        return v
    if isinstance(v, str) and (not v.strip() or v.strip().isdigit()):
        return int(v.strip() or 0)
    raise PyReasonFileError(f"Invalid {what} '{value}' (a time: an integer >= 0)", loc.file, loc.line, loc.column,
                            line)


def _checked(f: PFact, line: str | None, where: SourceLoc) -> PFact:
    if f.end < f.start and not f.static:
        raise PyReasonFileError(f"fact {f.name}: end_time {f.end} is before start_time {f.start} (PyReason "
                                "would never apply it)", where.file, where.line, where.column, line)
    return f


def _facts_csv(text: str, file: str, on_error: OnError) -> list[PFact]:
    def fact(row: CsvRow) -> PFact:
        src = row.source
        if not row.fields[0].strip():
            raise PyReasonFileError(f"Row {row.line}: Missing required 'fact_text'", file, row.line, 1, src)
        lit = parse_fact(row.fields[0], row.at(0), src)
        name = row.field(1).strip() or f"fact_{len(out)}"
        start = or_default(lambda: _time(row.field(2), "start_time", row.at(2), src), 0, on_error)
        end = or_default(lambda: _time(row.field(3), "end_time", row.at(3), src), 0, on_error)
        static = or_default(lambda: parse_bool(row.field(4), "static", row.at(4), src), False, on_error)
        return _checked(PFact(name, lit, start, end, static, row.at(0)), src, row.at(3))
    out: list[PFact] = []
    for row in csv_rows(text, file, ["fact_text", "name", "start_time", "end_time", "static"]):
        out += each_row([row], fact, on_error, "fact")
    return out


def _facts_json(text: str, file: str, on_error: OnError) -> list[PFact]:
    def fact(item: tuple[int, object, SourceLoc, JsonFinder]) -> PFact:
        i, obj, loc, finder = item
        src = finder.line(loc.line)
        lit = parse_fact(required_text(i, obj, "fact_text", loc, finder), loc, src)
        assert isinstance(obj, dict)
        name = str(obj.get("name") or f"fact_{len(out)}")
        start, end = (or_default(lambda k=k: _time(obj.get(k, 0), k, loc, src), 0, on_error)
                      for k in ("start_time", "end_time"))
        static = obj.get("static", False)
        if isinstance(static, str):
            static = or_default(lambda: parse_bool(static, "static", loc, src or ""), False, on_error)
        return _checked(PFact(name, lit, start, end, bool(static), loc), src, loc)
    out: list[PFact] = []
    for item in json_items(text, file, "fact_text", "fact"):
        out += each_row([item], fact, on_error, "fact")
    return out
