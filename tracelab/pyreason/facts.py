"""PyReason's facts: the fact text (`popular(Mary) : true`, `~p(a)`, `link(a,b):[0.5,1]`) with a name, a
start and an end time (both included) and a static flag, read from PyReason's CSV fact files
(`fact_text,name,start_time,end_time,static`, the header optional) or its JSON fact files (a list of
objects with those keys). Any other extension reads as the CSV format."""
from __future__ import annotations

import os
from dataclasses import dataclass

from tracelab.engine.errors import RuleSyntaxError
from tracelab.engine.parser import read_rule_file
from tracelab.engine.program import SourceLoc

from .files import csv_rows, json_items, parse_bool
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


def read_facts(path: str | os.PathLike[str]) -> list[PFact]:
    file = os.fspath(path)
    text = read_rule_file(file)
    if os.path.splitext(file)[1].lower() == ".json":
        return _facts_json(text, file)
    return _facts_csv(text, file)


def _time(value: str, what: str, loc: SourceLoc, line: str | None) -> int:
    v = value.strip()
    if not v:
        return 0
    if not v.isdigit():
        raise RuleSyntaxError(f"{what} '{value}' is not a time (an integer >= 0)", loc.file, loc.line,
                              loc.column, line)
    return int(v)


def _checked(f: PFact, line: str | None, where: SourceLoc) -> PFact:
    if f.end < f.start and not f.static:
        raise RuleSyntaxError(f"fact {f.name}: end_time {f.end} is before start_time {f.start} (PyReason "
                              "would never apply it)", where.file, where.line, where.column, line)
    return f


def _facts_csv(text: str, file: str) -> list[PFact]:
    out: list[PFact] = []
    for row in csv_rows(text, file, ["fact_text", "name", "start_time", "end_time", "static"]):
        src = row.source
        lit = parse_fact(row.fields[0], row.at(0), src)
        name = row.field(1).strip() or f"fact_{len(out)}"
        start = _time(row.field(2), "start_time", row.at(2), src)
        end = _time(row.field(3), "end_time", row.at(3), src)
        static = parse_bool(row.field(4), "static", row.at(4), src)
        out.append(_checked(PFact(name, lit, start, end, static, row.at(0)), src, row.at(3)))
    return out


def _facts_json(text: str, file: str) -> list[PFact]:
    out: list[PFact] = []
    for _, obj, loc, finder in json_items(text, file, "fact_text", "fact"):
        src = finder.line(loc.line)
        lit = parse_fact(obj["fact_text"], loc, src)
        name = str(obj.get("name") or f"fact_{len(out)}")
        times = []
        for key in ("start_time", "end_time"):
            v = obj.get(key, 0)
            if v is None or v == "":
                v = 0
            if isinstance(v, bool) or not (isinstance(v, int) or (isinstance(v, str) and v.strip().isdigit())) \
                    or int(v) < 0:
                raise finder.error(loc, f"fact {name}: {key} {v!r} is not a time (an integer >= 0)")
            times.append(int(v))
        static = obj.get("static", False)
        static = parse_bool(static, "static", loc, src or "") if isinstance(static, str) else bool(static)
        out.append(_checked(PFact(name, lit, times[0], times[1], static, loc), src, loc))
    return out
