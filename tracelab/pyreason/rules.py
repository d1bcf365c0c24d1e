"""PyReason's rules: the rule text (`popular(x) <-1 popular(y), Friends(x,y)`), read from its three file
formats: a text file (one rule a line, `#` comment lines, rules named rule_0, rule_1, ...), a CSV file
(`rule_text,name,infer_edges,set_static`) and a JSON file (a list of objects that may also carry
`custom_thresholds` and `weights`). docs/pyreason.md says what maps to what."""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

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
from .text import PLiteral, Squeezed, parse_literal, split_top

QUANTIFIERS = ("greater_equal", "greater", "less_equal", "less", "equal")


@dataclass(frozen=True)
class Threshold:
    """PyReason's `Threshold(quantifier, (number|percent, total|available), thresh)`."""
    quantifier: str
    kind: str  # number | percent
    over: str  # total | available
    value: float

    @property
    def is_default(self) -> bool:
        """PyReason's default on every clause: at least one grounding (an ordinary clause)."""
        return (self.quantifier, self.kind, self.over, self.value) == ("greater_equal", "number", "total", 1)


FORALL = Threshold("greater_equal", "percent", "total", 100)


@dataclass
class PRule:
    name: str
    head: PLiteral
    delay: int
    body: list[PLiteral]
    loc: SourceLoc
    text: str
    thresholds: list[Threshold] = field(default_factory=list)  # one per body clause
    set_static: bool = False
    infer_edges: bool = False
    weights: list[float] | None = None


def parse_rule(text: str, name: str, loc: SourceLoc, source_line: str | None = None) -> PRule:
    """One rule text at `loc` (the column where the text starts in its line)."""
    sq = Squeezed(text, loc, source_line)
    s = sq.s
    if not s:
        raise sq.error(0, "empty rule")
    arrow = s.find("<-")
    if arrow < 0:
        raise sq.error(len(s), "expected '<-' between the head and the body")
    if s.find("<-", arrow + 2) >= 0:
        raise sq.error(s.find("<-", arrow + 2), "a rule has one '<-'")
    if arrow == 0:
        raise sq.error(0, "the rule has no head")
    head = parse_literal(sq, 0, arrow, "head", allow_function=True)
    k = arrow + 2
    while k < len(s) and s[k].isdigit():
        k += 1
    delay = int(s[arrow + 2:k]) if k > arrow + 2 else 0
    if k == len(s):
        raise sq.error(k, "a rule without a body is not supported by tracelab (it needs a body clause)")
    body: list[PLiteral] = []
    for lo, hi in split_top(sq, k, len(s)):
        if lo == hi:
            raise sq.error(lo, "empty body clause (a trailing or double comma)")
        if s.startswith("forall(", lo):
            if not s.endswith(")", lo, hi) or hi - 1 <= lo + 7:
                raise sq.error(lo, "expected forall(pred(vars))")
            body.append(_forall(parse_literal(sq, lo + 7, hi - 1, "body clause")))
        else:
            body.append(parse_literal(sq, lo, hi, "body clause"))
    return PRule(name, head, delay, body, loc, text.strip(),
                 thresholds=[FORALL if c.forall else Threshold("greater_equal", "number", "total", 1)
                             for c in body])


def _forall(lit: PLiteral) -> PLiteral:
    return PLiteral(lit.pred, lit.args, lit.lower, lit.upper, lit.column, forall=True)


# ------------------------------------------------------------------------------------------ the files

def read_rules(path: str | os.PathLike[str], on_error: OnError = None) -> list[PRule]:
    """A PyReason rule file by its extension: .csv, .json, else the text format. A bad row raises
    (located), or with `on_error` is reported and skipped (a bad option: reported, its default used)."""
    file = os.fspath(path)
    text = read_rule_file(file)
    ext = os.path.splitext(file)[1].lower()
    if ext == ".csv":
        return _rules_csv(text, file, on_error)
    if ext == ".json":
        return _rules_json(text, file, on_error)
    return _rules_txt(text, file, on_error)


def read_rules_txt(path: str | os.PathLike[str], on_error: OnError = None, first: int = 0) -> list[PRule]:
    """A PyReason rule text file whatever its extension (PyReason's add_rules_from_file); its rules are
    named rule_<first>, rule_<first + 1>, ... by line, as PyReason names them."""
    file = os.fspath(path)
    return _rules_txt(read_rule_file(file), file, on_error, first)


def _rules_txt(text: str, file: str, on_error: OnError, first: int = 0) -> list[PRule]:
    """PyReason's add_rules_from_file: each line that is not blank and does not start with '#'."""
    lines = [(n, line) for n, line in enumerate(text.splitlines(), 1) if line.rstrip() and line.rstrip()[0] != "#"]
    return each_row(enumerate(lines), lambda item: parse_rule(item[1][1].rstrip(), f"rule_{first + item[0]}",
                                                                SourceLoc(file, item[1][0], 1), item[1][1]),
                    on_error, "rule")


def _rules_csv(text: str, file: str, on_error: OnError) -> list[PRule]:
    def rule(row: CsvRow) -> PRule:
        if not row.fields[0].strip():
            raise PyReasonFileError(f"Row {row.line}: Missing required 'rule_text'", file, row.line, 1, row.source)
        name = row.field(1).strip() or f"rule_{len(rules)}"
        r = parse_rule(row.fields[0], name, row.at(0), row.source)
        r.infer_edges = or_default(lambda: parse_bool(row.field(2), "infer_edges", row.at(2), row.source), False,
                                   on_error)
        r.set_static = or_default(lambda: parse_bool(row.field(3), "set_static", row.at(3), row.source), False,
                                  on_error)
        return r
    rules: list[PRule] = []
    for row in csv_rows(text, file, ["rule_text", "name", "infer_edges", "set_static"]):
        rules += each_row([row], rule, on_error, "rule")
    return rules


def _rules_json(text: str, file: str, on_error: OnError) -> list[PRule]:
    def rule(item: tuple[int, object, SourceLoc, JsonFinder]) -> PRule:
        i, obj, loc, finder = item
        r_text = required_text(i, obj, "rule_text", loc, finder)
        assert isinstance(obj, dict)
        name = str(obj.get("name") or f"rule_{len(rules)}")
        r = parse_rule(r_text, name, loc, finder.line(loc.line))
        r.infer_edges = or_default(lambda: _json_bool(obj, "infer_edges", loc, finder), False, on_error)
        r.set_static = or_default(lambda: _json_bool(obj, "set_static", loc, finder), False, on_error)
        r.thresholds = _json_thresholds(obj.get("custom_thresholds"), r, loc, finder)
        w = obj.get("weights")
        if w is not None:
            if not isinstance(w, list) or len(w) != len(r.body) or not all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) and x >= 0 for x in w):
                raise finder.error(loc, f"rule {name}: 'weights' must be {len(r.body)} numbers >= 0, one per "
                                        "body clause")
            r.weights = [float(x) for x in w]
        return r
    rules: list[PRule] = []
    for item in json_items(text, file, "rule_text", "rule"):
        rules += each_row([item], rule, on_error, "rule")
    return rules


def _json_bool(obj: dict, key: str, loc: SourceLoc, finder: JsonFinder) -> bool:
    v = obj.get(key, False)
    if isinstance(v, bool):
        return v
    if isinstance(v, str):
        return parse_bool(v, key, loc, finder.line(loc.line) or "")
    if isinstance(v, (int, float)):
        return bool(v)
    raise finder.error(loc, f"Invalid {key} value type '{type(v).__name__}' (a boolean)")


def _json_thresholds(raw: object, r: PRule, loc: SourceLoc, finder: JsonFinder) -> list[Threshold]:
    """custom_thresholds: a list (one per clause) or a dict {clause index: threshold}; the others keep
    PyReason's default (at least one)."""
    out = list(r.thresholds)
    if raw is None:
        return out
    n = len(r.body)
    if isinstance(raw, list):
        if len(raw) != n:
            raise finder.error(loc, f"rule {r.name}: {len(raw)} custom thresholds for {n} body clauses")
        items = list(enumerate(raw))
    elif isinstance(raw, dict) and raw:
        items = []
        for k, v in raw.items():
            try:
                i = int(k)
            except ValueError:
                raise finder.error(loc, f"rule {r.name}: custom_thresholds key '{k}' is not a clause index") from None
            if not 0 <= i < n:
                raise finder.error(loc, f"rule {r.name}: custom_thresholds key {i} is not a clause (0..{n - 1})")
            items.append((i, v))
    else:
        raise finder.error(loc, f"rule {r.name}: custom_thresholds must be a list or a non-empty object")
    for i, t in items:
        try:
            q, (kind, over), value = t["quantifier"], t["quantifier_type"], t["thresh"]
        except (TypeError, KeyError, ValueError):
            raise finder.error(loc, f"rule {r.name}: threshold of clause {i} needs 'quantifier', "
                                    "'quantifier_type' [number|percent, total|available] and 'thresh'") from None
        if q not in QUANTIFIERS or kind not in ("number", "percent") or over not in ("total", "available") \
                or isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
            raise finder.error(loc, f"rule {r.name}: threshold of clause {i} is not valid: {json.dumps(t)}")
        out[i] = Threshold(q, kind, over, value)
    return out
