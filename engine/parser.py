"""The rule-language front end (docs/language.md): a tokenizer, a recursive-descent parser and the checks
made once per program. Every error names FILE:LINE:COL and says what was expected."""
from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from itertools import groupby
from pathlib import Path

from . import annotations, head_functions
from .errors import ProgramCheckError, RuleSyntaxError
from .parse_limit import ParseBudget
from .safe_files import MIB, read_bytes
from .vocabulary import MAX_LABELS
from .program import (
    COMPARISONS,
    CONSTANT_RE,
    EDGE_HEAD_MODES,
    INCONSISTENCY_POLICIES,
    MAX_BINDING_CLAUSES,
    MAX_TIME,
    PREDICATE_RE,
    TIMESTEP_MODES,
    UPDATE_MODES,
    Fact,
    Literal,
    Program,
    Quantifier,
    Rule,
    SourceLoc,
    Term,
    constant_text,
)

__all__ = ["parse_program", "load_program", "parse_literal", "check_program"]

VARIABLE_RE = re.compile(r"[A-Z_][A-Za-z0-9_]*")
STATEMENT_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")

DIRECTIVES = {"mode": UPDATE_MODES, "timesteps": TIMESTEP_MODES, "inconsistency": INCONSISTENCY_POLICIES,
              "edge_heads": EDGE_HEAD_MODES}
LIST_DIRECTIVES = ("closed",)  # `%closed p, q`: a list of predicates, repeatable
RULE_FLAGS = ("set_static", "infer_edges")  # rule options that switch a behaviour on
RULE_OPTIONS = (*UPDATE_MODES, *RULE_FLAGS)  # `{override}` / `{intersection}`, `{set_static}`, `{infer_edges}`
# the largest rule or fact file read (a whole file is parsed in memory, ~1 KB of objects per statement): the
# rule files here are a few KB; big fact sets go in fact tables (load_fact_table), which have no such cap
RULE_FILE_CAP = 64 * MIB
WEIGHTS_OPTION = "weights"  # `{weights=1,2,0.5}`: per-clause weights of the annotation function

# ---------------------------------------------------------------------------------------------- tokens

NAME, NUMBER, QUOTED, ARROW, PUNCT, NL, EOF = "name", "number", "quoted", "arrow", "punct", "nl", "eof"
CMP = "cmp"

_TOKEN_RE = re.compile(r"""
    (?P<ws>[ \t\f\r\v]+)
  | (?P<comment>\#.*)
  | (?P<dotdot>\.\.)                      # before numbers: `@2..5` is 2, .., 5
  | (?P<number>[0-9]+\.[0-9]+|\.[0-9]+)  # decimals only; plain digits are names (`16` is also a constant)
  | (?P<arrow><-(?:[0-9]+|!))
  | (?P<badarrow><-)
  | (?P<cmp>>=|<=|==|>|<)                # quantifiers: `[>= 50%] p(Y)`
  | (?P<name>[A-Za-z0-9_][A-Za-z0-9_-]*)
  | (?P<quoted>"[^"]*"|'[^']*')
  | (?P<badquote>["'])
  | (?P<punct>[()\[\],:~@{}%=\\-])
""", re.VERBOSE)


@dataclass(frozen=True, slots=True)
class Token:
    kind: str
    text: str  # as written (a quoted constant keeps its quotes)
    line: int
    col: int

    @property
    def end(self) -> int:
        return self.col + len(self.text)

    def is_punct(self, text: str) -> bool:
        return self.kind == PUNCT and self.text == text

    def describe(self) -> str:
        if self.kind == NL:
            return "end of line"
        if self.kind == EOF:
            return "end of file"
        return self.text if self.kind == QUOTED else f"'{self.text}'"


def _tokenize(lines: list[str], file: str) -> list[Token]:
    """Tokens of the whole text. NL ends a statement; it is dropped after a line that ends with `\\` (the
    backslash is dropped too), `,` or an arrow, so a statement continues on the next non-blank line."""
    out: list[Token] = []
    for n, line in enumerate(lines, 1):
        toks = list(_scan_line(line, n, file, lines))
        if not toks:
            continue  # blank or comment-only: no NL, so it neither ends nor breaks a continued statement
        for t in toks[:-1]:
            if t.is_punct("\\"):
                raise _syntax(file, lines, t.line, t.col,
                              "'\\' continues a statement on the next line and must end its line")
        last = toks[-1]
        continued = last.is_punct("\\") or last.is_punct(",") or last.kind == ARROW
        if last.is_punct("\\"):
            toks.pop()
        out.extend(toks)
        if not continued:
            out.append(Token(NL, "", n, last.end))
    if out:
        last = out[-1]
        out.append(Token(EOF, "", last.line, last.end if last.kind != NL else last.col))
    else:
        out.append(Token(EOF, "", 1, 1))
    return out


def _scan_line(line: str, n: int, file: str, lines: list[str]) -> Iterator[Token]:
    pos = 0
    while pos < len(line):
        m = _TOKEN_RE.match(line, pos)
        if m is None:
            raise _syntax(file, lines, n, pos + 1, f"unexpected character {line[pos]!r}")
        kind, text, col = m.lastgroup, m.group(), pos + 1
        pos = m.end()
        if kind in ("ws", "comment"):
            continue
        if kind == "badquote":
            raise _syntax(file, lines, n, col, f"unterminated quoted constant: no closing {text} on this line")
        if kind == "badarrow":
            neg = re.match(r"-[0-9]+", line[pos:])
            if neg:
                raise _check_err(file, lines, n, pos + 1,
                                 f"the delay must be an integer >= 0, found {neg.group()}")
            raise _syntax(file, lines, n, pos + 1,
                          "expected a delay right after '<-': an integer >= 0 ('<-0', '<-1') or '!' (immediate)")
        yield Token({"dotdot": PUNCT}.get(kind, kind), text, n, col)


def _syntax(file: str, lines: list[str], line: int, col: int, msg: str) -> RuleSyntaxError:
    return RuleSyntaxError(msg, file, line, col, _line_of(lines, line))


def _check_err(file: str, lines: list[str], line: int, col: int, msg: str) -> ProgramCheckError:
    return ProgramCheckError(msg, file, line, col, _line_of(lines, line))


def _line_of(lines: list[str], line: int) -> str | None:
    return lines[line - 1] if 0 < line <= len(lines) else None


def line_from_file(file: str, line: int) -> str | None:
    """Line `line` of a rule file read again for a message, or None if it cannot be read as one."""
    try:
        return _line_of(_split_lines(read_rule_file(file)), line)
    except (OSError, ValueError):  # "<string>", a file gone or changed since: the message still names the position
        return None


def _split_lines(text: str) -> list[str]:
    # not str.splitlines(): it also splits on \f, \x1c, U+2028 ..., which editors do not count as lines
    return [ln[:-1] if ln.endswith("\r") else ln for ln in text.removeprefix("\ufeff").split("\n")]


# ---------------------------------------------------------------------------------------------- parser

@dataclass
class _Unit:
    """One parsed file, before names are assigned and the program is checked."""
    file: str
    lines: list[str]
    items: list[Rule | Fact] = field(default_factory=list)  # in file order; name "" = unnamed
    directives: list[tuple[str, str, SourceLoc]] = field(default_factory=list)
    closed: list[tuple[str, SourceLoc]] = field(default_factory=list)  # `%closed` predicates, in order
    arg_locs: dict[int, tuple[Literal, tuple[SourceLoc, ...]]] = field(default_factory=dict)


class _Parser:
    def __init__(self, text: str, file: str) -> None:
        self.unit = _Unit(file, _split_lines(text))
        self.toks = _tokenize(self.unit.lines, file)
        self.i = 0
        self.head_function: Token | None = None  # set by literal() when a head names an annotation function

    # -- token helpers
    def peek(self, k: int = 0) -> Token:
        return self.toks[min(self.i + k, len(self.toks) - 1)]

    def take(self) -> Token:
        t = self.peek()
        self.i = min(self.i + 1, len(self.toks) - 1)
        return t

    def at_end(self) -> bool:
        return self.peek().kind in (NL, EOF)

    def loc(self, t: Token) -> SourceLoc:
        return SourceLoc(self.unit.file, t.line, t.col)

    def syntax(self, t: Token, msg: str) -> RuleSyntaxError:
        return _syntax(self.unit.file, self.unit.lines, t.line, t.col, msg)

    def check(self, t: Token, msg: str) -> ProgramCheckError:
        return _check_err(self.unit.file, self.unit.lines, t.line, t.col, msg)

    def expect_punct(self, text: str, context: str) -> Token:
        t = self.peek()
        if not t.is_punct(text):
            raise self.syntax(t, f"expected '{text}' {context}, found {t.describe()}")
        return self.take()

    def text_of(self, first: int, last: int) -> str:
        """Source text of tokens first..last-1, one segment per physical line joined by a space (comments
        and continuation backslashes are not tokens, so they are left out)."""
        parts = []
        for line, group in groupby(self.toks[first:last], key=lambda t: t.line):
            g = list(group)
            parts.append(self.unit.lines[line - 1][g[0].col - 1: g[-1].end - 1])
        return " ".join(parts)

    # -- statements
    def parse_file(self) -> _Unit:
        while True:
            t = self.peek()
            if t.kind == EOF:
                return self.unit
            if t.kind == NL:
                self.take()
            elif t.is_punct("%"):
                self.directive()
            else:
                self.unit.items.append(self.statement())

    def directive(self) -> None:
        pct = self.take()
        name = self.peek()
        if name.kind == NAME and name.text in LIST_DIRECTIVES:
            self.closed_directive(pct)
            return
        if name.kind != NAME or name.text not in DIRECTIVES:
            known = ", ".join(f"%{d}" for d in (*DIRECTIVES, *LIST_DIRECTIVES))
            what = f"unknown directive '%{name.text}'" if name.kind == NAME else \
                f"expected a directive name after '%', found {name.describe()}"
            raise self.syntax(name, f"{what} (expected one of {known})")
        self.take()
        allowed = DIRECTIVES[name.text]
        value = self.peek()
        if value.kind != NAME:
            raise self.syntax(value, f"expected a value for %{name.text} ({' | '.join(allowed)}), "
                                     f"found {value.describe()}")
        if value.text not in allowed:
            raise self.check(value, f"unknown value '{value.text}' for %{name.text} "
                                    f"(expected {' | '.join(allowed)})")
        self.take()
        if not self.at_end():
            raise self.syntax(self.peek(), f"expected end of line after '%{name.text} {value.text}', "
                                           f"found {self.peek().describe()}")
        self.unit.directives.append((name.text, value.text, self.loc(pct)))

    def closed_directive(self, pct: Token) -> None:
        """`%closed p` or `%closed p, q, ...`: predicates whose unset atoms read as [0,0] in bodies."""
        self.take()  # 'closed'
        while True:
            t = self.peek()
            if t.kind != NAME or not PREDICATE_RE.fullmatch(t.text):
                what = f"invalid predicate name '{t.text}'" if t.kind == NAME else f"found {t.describe()}"
                raise self.syntax(t, f"expected a predicate name after '%closed' or ',' ({what})")
            self.take()
            self.unit.closed.append((t.text, self.loc(t)))
            if self.at_end():
                return
            if not self.peek().is_punct(","):
                raise self.syntax(self.peek(), f"expected ',' or end of line after a predicate of %closed, "
                                               f"found {self.peek().describe()}")
            self.take()

    def statement(self) -> Rule | Fact:
        first_i = self.i
        first = self.peek()
        name = ""
        if first.kind == NAME and self.peek(1).is_punct(":"):
            if not STATEMENT_NAME_RE.fullmatch(first.text):
                raise self.syntax(first, f"invalid name '{first.text}': a rule or fact name starts with a "
                                         "letter or '_' and contains letters, digits, '_' and '-'")
            name = first.text
            self.i += 2
        elif first.kind != NAME and not first.is_punct("~"):
            raise self.syntax(first, f"expected a rule, a fact or a directive, found {first.describe()}")
        head = self.literal("", allow_function=True)
        function, self.head_function = self.head_function, None
        if self.peek().kind == ARROW:
            return self.rule_rest(name, head, first, first_i, function)
        if function is not None:
            raise self.syntax(function, "an annotation function names how a rule head's bound is computed: "
                                        "it needs a rule ('<-k' or '<-!' after the head), a fact takes ':[l,u]'")
        return self.fact_rest(name, head, first, first_i)

    def rule_rest(self, name: str, head: Literal, first: Token, first_i: int, function: Token | None) -> Rule:
        arrow = self.take()
        immediate = arrow.text == "<-!"
        delay = 0 if immediate else int(arrow.text[2:])
        if delay > MAX_TIME:
            raise self.check(arrow, f"the delay {delay} is too large: a delay is at most {MAX_TIME}")
        quants = [self.quantifier()]
        body = [self.literal(f" after '{arrow.text}'")]
        options: dict[str, object] = {}
        while True:
            t = self.peek()
            if t.is_punct(","):
                self.take()
                quants.append(self.quantifier())
                body.append(self.literal(" after ','"))
            elif t.is_punct("{"):
                options = self.options()
                if not self.at_end():
                    raise self.syntax(self.peek(), "expected end of rule after the options, "
                                                   f"found {self.peek().describe()}")
                break
            elif self.at_end():
                break
            else:
                raise self.syntax(t, f"expected ',', '{{' or end of rule after body literal, found {t.describe()}")
        if function is not None and not annotations.is_known(function.text):
            raise self.check(function, f"unknown annotation function '{function.text}' (built in: "
                                       f"{', '.join(annotations.BUILTINS)}; register others with "
                                       "tracelab.engine.register_annotation before parsing)")
        return Rule(name, head, tuple(body), delay=delay, immediate=immediate,
                    loc=self.loc(first), text=self.text_of(first_i, self.i),
                    quantifiers=tuple(quants) if any(q is not None for q in quants) else (),
                    annotation=function.text if function is not None else None, **options)

    def quantifier(self) -> Quantifier | None:
        """An optional `[op count[%] [available|total]]` or `[forall [available|total]]` before a clause."""
        if not self.peek().is_punct("["):
            return None
        bracket = self.take()
        t = self.peek()
        if t.kind == NAME and t.text == "forall":
            self.take()
            op, value, percent = "==", 100.0, True
        elif t.kind == CMP:
            op = self.take().text
            n = self.peek()
            if n.kind != NUMBER and not (n.kind == NAME and n.text.isdigit()):
                raise self.syntax(n, f"expected a count (an integer) or a percentage ('50%') after '{op}', "
                                     f"found {n.describe()}")
            self.take()
            percent = self.peek().is_punct("%")
            if percent:
                self.take()
            elif n.kind == NUMBER:
                raise self.check(n, f"a count is an integer, found {n.text} (write '{n.text}%' for a percentage)")
            value = float(n.text)
            if percent and value > 100.0:
                raise self.check(n, f"a percentage is at most 100%, found {n.text}%")
        else:
            raise self.syntax(t, "expected a quantifier after '[': a comparison (>=, >, <=, <, ==) with a count "
                                 f"or a percentage, or 'forall'; found {t.describe()}")
        available = False
        w = self.peek()
        if w.kind == NAME and w.text in ("available", "total"):
            available = w.text == "available"
            self.take()
        self.expect_punct("]", "to close the quantifier (after the count, 'available' or 'total')")
        return Quantifier(op, value, percent, available, loc=self.loc(bracket))

    def options(self) -> dict[str, object]:
        """`{opt, opt, ...}`: the Rule fields they set (mode, set_static, infer_edges, weights)."""
        self.take()  # '{'
        out: dict[str, object] = {}
        expected = " | ".join([*RULE_OPTIONS, f"{WEIGHTS_OPTION}=w1,w2,..."])
        while True:
            t = self.peek()
            if t.kind != NAME:
                raise self.syntax(t, f"expected a rule option ({expected}), found {t.describe()}")
            if t.text == WEIGHTS_OPTION:
                if "weights" in out:
                    raise self.check(t, "the option 'weights' is given twice")
                self.take()
                self.expect_punct("=", "after 'weights' (weights=w1,w2,...: one number per body clause)")
                out["weights"] = self.weight_list()
            elif t.text not in RULE_OPTIONS:
                raise self.check(t, f"unknown rule option '{t.text}' (expected {expected})")
            else:
                if t.text in RULE_FLAGS:
                    out[t.text] = True
                else:
                    if out.get("mode", t.text) != t.text:
                        raise self.check(t, f"conflicting rule options '{out['mode']}' and '{t.text}'")
                    out["mode"] = t.text
                self.take()
            if self.peek().is_punct(","):
                self.take()
                continue
            self.expect_punct("}", "or ',' after a rule option")
            return out

    def weight_list(self) -> tuple[float, ...]:
        """`1,2,0.5` after `weights=`: numbers >= 0, up to the first ',' not followed by a number."""
        out = []
        while True:
            n = self.peek()
            if n.is_punct("-"):
                raise self.check(n, "a weight is a number >= 0")
            if n.kind != NUMBER and not (n.kind == NAME and n.text.isdigit()):
                raise self.syntax(n, f"expected a weight (a number >= 0), found {n.describe()}")
            self.take()
            out.append(float(n.text))
            nxt = self.peek(1)
            if self.peek().is_punct(",") and (nxt.kind == NUMBER or (nxt.kind == NAME and nxt.text.isdigit())
                                              or nxt.is_punct("-")):
                self.take()
                continue
            return tuple(out)

    def fact_rest(self, name: str, lit: Literal, first: Token, first_i: int) -> Fact:
        start = end = 0
        window: Token | None = None
        static: Token | None = None
        while not self.at_end():
            t = self.peek()
            if t.is_punct("@") and window is None:
                window = self.take()
                start, end = self.window(window)
            elif t.kind == NAME and t.text == "static" and static is None:
                static = self.take()
            else:
                opts = _alternatives([*(["'@time'"] if window is None else []),
                                      *(["'static'"] if static is None else []), "end of line"])
                if window is None and static is None:
                    raise self.syntax(t, f"expected '<-k' or '<-!' (a rule), or {opts} (a fact) after the "
                                         f"literal, found {t.describe()}")
                raise self.syntax(t, f"expected {opts} in a fact, found {t.describe()}")
        if static is not None and window is not None and end != start:
            raise self.check(window, "a static fact holds from its time on: give it one time '@t', "
                                     f"not a window '@{start}..{end}'")
        return Fact(name, lit, start=start, end=end, static=static is not None,
                    loc=self.loc(first), text=self.text_of(first_i, self.i))

    def window(self, at: Token) -> tuple[int, int]:
        start = self.time("after '@'")
        end = start
        if self.peek().is_punct(".."):
            self.take()
            end = self.time("after '..'")
        if end < start:
            raise self.check(at, f"empty window @{start}..{end}: the start must be <= the end")
        return start, end

    def time(self, context: str) -> int:
        t = self.peek()
        if t.is_punct("-") and self.peek(1).kind == NAME and self.peek(1).text.isdigit():
            raise self.check(t, f"a time is an integer >= 0, found -{self.peek(1).text}")
        if t.kind != NAME or not t.text.isdigit():
            raise self.syntax(t, f"expected a time (an integer >= 0) {context}, found {t.describe()}")
        self.take()
        if int(t.text) > MAX_TIME:
            raise self.check(t, f"the time {t.text} is too large: a time is at most {MAX_TIME}")
        return int(t.text)

    # -- literals
    def literal(self, context: str, allow_function: bool = False) -> Literal:
        first = self.peek()
        negated = first.is_punct("~")
        if negated:
            self.take()
        p = self.peek()
        if p.kind != NAME:
            raise self.syntax(p, f"expected a literal{context}, found {p.describe()}")
        if not PREDICATE_RE.fullmatch(p.text):
            raise self.syntax(p, f"invalid predicate name '{p.text}': a predicate starts with a lower-case "
                                 "letter and contains letters, digits and '_'")
        self.take()
        self.expect_punct("(", f"after predicate '{p.text}'")
        args: list[Term] = []
        locs: list[SourceLoc] = []
        while True:
            t = self.peek()
            args.append(self.term(allow_call=allow_function))
            locs.append(self.loc(t))
            t = self.peek()
            if t.is_punct(")"):
                self.take()
                break
            if not t.is_punct(","):
                raise self.syntax(t, f"expected ',' or ')' after an argument of '{p.text}', found {t.describe()}")
            if len(args) == 2:
                raise self.syntax(t, "expected ')' after the second argument: a literal has one argument "
                                     "(a node label) or two (an edge label)")
            self.take()
        lower = upper = 1.0
        if self.peek().is_punct(":"):
            self.take()
            fn = self.peek()
            if allow_function and fn.kind == NAME and PREDICATE_RE.fullmatch(fn.text):  # `p(X):average`
                self.head_function = self.take()
            else:
                lower, upper = self.bound()
        lit = Literal(p.text, tuple(args), lower, upper, negated, loc=self.loc(first))
        self.unit.arg_locs[id(lit)] = (lit, tuple(locs))
        return lit

    def term(self, allow_call: bool = False) -> Term:
        """A constant or a variable; in a rule head (`allow_call`) also a head function call `f(X, b)`."""
        t = self.peek()
        if t.kind == NAME and PREDICATE_RE.fullmatch(t.text) and self.peek(1).is_punct("("):
            if not allow_call:
                raise self.syntax(t, f"'{t.text}(' is a head function call, which only a rule head's argument "
                                     "may be")
            return self.call()
        if t.kind == QUOTED:
            if len(t.text) == 2:
                raise self.syntax(t, "empty quoted constant")
            self.take()
            return Term(t.text[1:-1], is_var=False)
        if t.kind == NAME:
            if VARIABLE_RE.fullmatch(t.text):
                self.take()
                return Term(t.text, is_var=True)
            if CONSTANT_RE.fullmatch(t.text):
                self.take()
                return Term(t.text, is_var=False)
            raise self.syntax(t, f"invalid variable name '{t.text}': a variable contains letters, digits "
                                 "and '_' (quote it to make it a constant)")
        hint = " (quote a constant that contains other characters)" if t.kind == NUMBER else ""
        raise self.syntax(t, f"expected an argument (a constant or a variable), found {t.describe()}{hint}")

    def call(self) -> Term:
        """`f(arg, ...)`: a head function applied to constants and variables (docs/language.md)."""
        fn = self.take()
        self.take()  # "("
        args = [self.term()]
        while self.peek().is_punct(","):
            self.take()
            args.append(self.term())
        self.expect_punct(")", f"after the arguments of head function '{fn.text}'")
        text = f"{fn.text}({','.join(constant_text(a.name) if not a.is_var else a.name for a in args)})"
        term = Term(text, is_var=False, function=fn.text, call_args=tuple(args))
        if (why := head_functions.check_call(term)) is not None:
            raise self.check(fn, why)
        return term

    def bound(self) -> tuple[float, float]:
        bracket = self.expect_punct("[", "after ':' (an annotation is ':[lower,upper]')")
        lower = self.number("lower")
        self.expect_punct(",", "between the lower and upper bound")
        upper = self.number("upper")
        self.expect_punct("]", "after the upper bound")
        if lower > upper:
            raise self.check(bracket, f"empty bound [{lower:g},{upper:g}]: the lower bound must be <= the upper")
        return lower, upper

    def number(self, which: str) -> float:
        t = self.peek()
        sign = 1.0
        if t.is_punct("-"):
            self.take()
            sign = -1.0
        n = self.peek()
        if n.kind != NUMBER and not (n.kind == NAME and n.text.isdigit()):
            raise self.syntax(n, f"expected the {which} bound (a number in [0,1]), found {n.describe()}")
        self.take()
        v = sign * float(n.text) + 0.0  # + 0.0 turns -0.0 into 0.0
        if not 0.0 <= v <= 1.0:
            raise self.check(t, f"the {which} bound {'-' if sign < 0 else ''}{n.text} is outside [0,1]")
        return v


# ------------------------------------------------------------------------------------------ public API

def parse_program(text: str, file: str = "<string>") -> Program:
    """Parse and check one program text; `file` is the name used in error locations."""
    ParseBudget().spend(file, text)
    return _build([_Parser(text, file).parse_file()])


def load_program(*paths: str | os.PathLike[str]) -> Program:
    """Parse the files and merge them into one program (facts and rules in the order of the paths), then
    check it. Directives must agree across files; names are unique across files."""
    if not paths:
        raise ValueError("load_program needs at least one file")
    texts = [(os.fspath(p), read_rule_file(os.fspath(p))) for p in paths]
    budget = ParseBudget()
    for file, text in texts:  # every file measured before any is parsed
        budget.spend(file, text)
    return _build([_Parser(text, file).parse_file() for file, text in texts])


def read_rule_file(file: str) -> str:
    """A rule or fact file's text (tracelab's or PyReason's): a regular file, refused past RULE_FILE_CAP
    (FileRefused: a FIFO is refused at once, not waited on); bytes that are not UTF-8 are a located error."""
    data = read_bytes(file, RULE_FILE_CAP, what="rule or fact file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        column = e.start - (data.rfind(b"\n", 0, e.start) + 1) + 1
        raise RuleSyntaxError(f"the file is not UTF-8 text: byte 0x{data[e.start]:02x} at byte offset "
                              f"{e.start} cannot be decoded (save the file as UTF-8)", file, line, column) from None


def parse_literal(text: str) -> Literal:
    """One literal, such as a query 'atLoc(red-agent-1,16)' or '~alarm(base):[0.5,1]'. Variables are
    allowed; nothing is checked beyond the syntax and the bound."""
    p = _Parser(text, "<literal>")
    lit = p.literal("")
    if p.peek().kind == NL:
        p.take()
    if p.peek().kind != EOF:
        raise p.syntax(p.peek(), f"expected end of literal, found {p.peek().describe()}")
    return lit


def check_program(program: Program, known_predicates: Mapping[str, int] | None = None) -> None:
    """Check a program (also one built in code) and recompute program.warnings. `known_predicates` maps
    predicates set elsewhere (graph attributes) to their arity. Raises ProgramCheckError."""
    _Checker(program, known_predicates or {}, {}, None).run()


# ------------------------------------------------------------------------------------ merging, naming

def _build(units: list[_Unit]) -> Program:
    sources = {u.file: u.lines for u in units}
    arg_locs = {k: v for u in units for k, v in u.arg_locs.items()}

    def fail(loc: SourceLoc, msg: str) -> ProgramCheckError:
        return ProgramCheckError(msg, loc.file, loc.line, loc.column, _line_of(sources[loc.file], loc.line))

    program = Program(files=[u.file for u in units])
    seen: dict[str, tuple[str, SourceLoc]] = {}
    for u in units:
        for key, value, loc in u.directives:
            if key in seen and seen[key][0] != value:
                raise fail(loc, f"conflicting %{key}: '{value}' here but '{seen[key][0]}' at {seen[key][1]}")
            seen.setdefault(key, (value, loc))
            setattr(program, key, value)
    program.closed = tuple(dict.fromkeys(pred for u in units for pred, _loc in u.closed))

    items = _named([it for u in units for it in u.items], fail)
    program.rules = [it for it in items if isinstance(it, Rule)]
    program.facts = [it for it in items if isinstance(it, Fact)]
    _Checker(program, {}, arg_locs, sources).run()
    return program


def _named(items: list[Rule | Fact], fail) -> list[Rule | Fact]:
    """Give unnamed statements `rule<line>` / `fact<line>`; when that name is taken (an explicit name, or
    the same line in an earlier file), `<stem>_rule<line>`, then `<stem>_rule<line>_2`, ..."""
    taken: dict[str, SourceLoc] = {}
    for it in items:
        if it.name:
            if it.name in taken:
                raise fail(it.loc, f"duplicate name '{it.name}' (first defined at {taken[it.name]})")
            taken[it.name] = it.loc
    out = []
    for it in items:
        if not it.name:
            base = f"{'rule' if isinstance(it, Rule) else 'fact'}{it.loc.line}"
            stem = re.sub(r"[^A-Za-z0-9_]+", "_", Path(it.loc.file).stem).strip("_") or "file"
            name, n = base, 1
            while name in taken:
                name = f"{stem}_{base}" + (f"_{n}" if n > 1 else "")
                n += 1
            taken[name] = it.loc
            it = dataclasses.replace(it, name=name)
        out.append(it)
    return out


# --------------------------------------------------------------------------------------------- checks

class _Checker:
    def __init__(self, program: Program, known: Mapping[str, int],
                 arg_locs: Mapping[int, tuple[Literal, tuple[SourceLoc, ...]]],
                 sources: Mapping[str, list[str]] | None) -> None:
        self.program, self.known, self.arg_locs, self.sources = program, known, arg_locs, sources
        self.arity: dict[str, tuple[int, SourceLoc | None]] = {p: (n, None) for p, n in known.items()}

    def fail(self, loc: SourceLoc | None, msg: str) -> ProgramCheckError:
        if loc is None:
            return ProgramCheckError(msg, self.program.files[0] if self.program.files else "<program>")
        if self.sources is not None:
            src = _line_of(self.sources.get(loc.file, []), loc.line)
        else:  # a program checked after parsing: read the line back from its file if there is one
            src = line_from_file(loc.file, loc.line)
        return ProgramCheckError(msg, loc.file, loc.line, loc.column, src)

    def arg_loc(self, lit: Literal, i: int) -> SourceLoc | None:
        entry = self.arg_locs.get(id(lit))
        return entry[1][i] if entry is not None and entry[0] is lit else lit.loc

    def run(self) -> None:
        p = self.program
        for attr, allowed in (("mode", UPDATE_MODES), ("timesteps", TIMESTEP_MODES),
                              ("inconsistency", INCONSISTENCY_POLICIES), ("edge_heads", EDGE_HEAD_MODES)):
            if getattr(p, attr) not in allowed:
                raise self.fail(None, f"unknown %{attr} '{getattr(p, attr)}' (expected {' | '.join(allowed)})")
        names: dict[str, SourceLoc | None] = {}
        for item in self.in_order():
            if item.name in names:
                raise self.fail(item.loc, f"duplicate name '{item.name}' (first defined at {names[item.name]})")
            names[item.name] = item.loc
            if isinstance(item, Fact):
                self.fact(item)
            else:
                self.rule(item)
            if len(self.arity) > MAX_LABELS:  # the vocabulary's limit: a label id has 15 bits
                kind = "fact" if isinstance(item, Fact) else "rule"
                raise self.fail(item.loc, f"{kind} '{item.name}' brings the predicates of the program (and its "
                                          f"graph) to {len(self.arity):,}: the engine takes at most {MAX_LABELS:,}")
        p.warnings = list(self.warnings())

    def in_order(self) -> list[Rule | Fact]:
        files = {f: i for i, f in enumerate(self.program.files)}

        def key(it: Rule | Fact) -> tuple[int, str, int, int]:
            loc = it.loc
            if loc is None:
                return (len(files) + 1, "", 0, 0)
            return (files.get(loc.file, len(files)), loc.file, loc.line, loc.column)
        return sorted([*self.program.facts, *self.program.rules], key=key)

    def literal(self, lit: Literal) -> None:
        n = len(lit.args)
        if not lit.pred:
            raise self.fail(lit.loc, "a literal needs a predicate name")
        if n not in (1, 2):
            raise self.fail(lit.loc, f"'{lit.pred}' has {n} arguments: a literal has one argument (a node "
                                     "label) or two (an edge label)")
        for i, t in enumerate(lit.args):
            if not t.name:
                raise self.fail(self.arg_loc(lit, i), "empty constant or variable name")
        if not (0.0 <= lit.lower <= lit.upper <= 1.0):  # also false for NaN
            raise self.fail(lit.loc, f"bound [{lit.lower:g},{lit.upper:g}] of '{lit.pred}': a bound [l,u] "
                                     "needs 0 <= l <= u <= 1")
        if lit.pred in self.arity and self.arity[lit.pred][0] != n:
            m, where = self.arity[lit.pred]
            at = f"at {where}" if where is not None else "in the graph"
            raise self.fail(lit.loc, f"predicate '{lit.pred}' is used with {_args(n)} here but with "
                                     f"{_args(m)} {at}")
        self.arity.setdefault(lit.pred, (n, lit.loc))

    def fact(self, f: Fact) -> None:
        self.literal(f.literal)
        for i, t in enumerate(f.literal.args):
            if t.function is not None:
                raise self.fail(self.arg_loc(f.literal, i), f"a fact must be ground: '{t.name}' is a head "
                                "function call, which only a rule head may hold")
            if t.is_var:
                raise self.fail(self.arg_loc(f.literal, i),
                                f"a fact must be ground: '{t.name}' is a variable (quote it, \"{t.name}\", "
                                "to use it as a constant)")
        if not (_is_int(f.start) and _is_int(f.end)) or f.start < 0:
            raise self.fail(f.loc, f"fact times are integers >= 0, found @{f.start}..{f.end}")
        if f.end > MAX_TIME:
            raise self.fail(f.loc, f"the time {f.end} is too large: a time is at most {MAX_TIME}")
        if f.start > f.end:
            raise self.fail(f.loc, f"empty window @{f.start}..{f.end}: the start must be <= the end")
        if f.static and f.start != f.end:
            raise self.fail(f.loc, f"a static fact holds from its time on: give it one time, not a window "
                                   f"@{f.start}..{f.end}")

    def rule(self, r: Rule) -> None:
        for lit in (r.head, *r.body):
            self.literal(lit)
        if not r.body:
            raise self.fail(r.loc, f"rule '{r.name}' has an empty body")
        if not _is_int(r.delay) or r.delay < 0:
            raise self.fail(r.loc, f"rule '{r.name}': the delay must be an integer >= 0, found {r.delay!r}")
        if r.delay > MAX_TIME:
            raise self.fail(r.loc, f"rule '{r.name}': the delay {r.delay} is too large: a delay is at most "
                                   f"{MAX_TIME}")
        n_binding = len(r.watched_clauses())
        if n_binding > MAX_BINDING_CLAUSES:
            raise self.fail(r.loc, f"rule '{r.name}' has {n_binding} binding body clauses; the engine allows "
                                   f"at most {MAX_BINDING_CLAUSES} (clauses whose bound contains [0,1] do not count)")
        if r.immediate and r.delay != 0:
            raise self.fail(r.loc, f"rule '{r.name}' is immediate ('<-!') so its delay is 0, not {r.delay}")
        if r.mode is not None and r.mode not in UPDATE_MODES:
            raise self.fail(r.loc, f"rule '{r.name}': unknown rule option '{r.mode}' "
                                   f"(expected {' | '.join(RULE_OPTIONS)})")
        self.aggregation(r)
        self.head_calls(r)
        binding = {v for ci in r.binding_clauses(self.program.closed) for v in r.body[ci].variables}
        for var in r.variables:
            if var in binding:
                continue
            lit, i = next((lit, i) for lit in (r.head, *r.body) for i, t in enumerate(lit.args)
                          if var in t.variables)
            quantified = [ci for ci, b in enumerate(r.body) if var in b.variables and r.quantifier(ci) is not None]
            if quantified:
                lit, i = next((r.body[ci], i) for ci in quantified
                              for i, t in enumerate(r.body[ci].args) if t.is_var and t.name == var)
                why = ("a variable of a quantified clause must occur in the head or in an unquantified "
                       "binding clause, which give the clause its candidates; it must occur in a body clause "
                       "whose bound excludes [0,1]")
            else:
                why = _unsafe_why(self.program, r, var)
            raise self.fail(self.arg_loc(lit, i), f"unsafe variable '{var}' in rule '{r.name}': {why}")

    def head_calls(self, r: Rule) -> None:
        """Head function calls: only in the head, of a registered function with its number of arguments,
        not in a rule evaluated per head grounding (docs/language.md, "Head functions")."""
        for lit in r.body:
            for i, t in enumerate(lit.args):
                if t.function is not None:
                    raise self.fail(self.arg_loc(lit, i), f"rule '{r.name}': a head function call ('{t.name}') "
                                    "may only be an argument of the rule head")
        for i, t in enumerate(r.head.args):
            if t.function is None:
                continue
            if (why := head_functions.check_call(t)) is not None:
                raise self.fail(self.arg_loc(r.head, i), f"rule '{r.name}': {why}")
            if r.aggregated:
                raise self.fail(self.arg_loc(r.head, i), f"rule '{r.name}': a head function call cannot be "
                                "combined with quantifiers or an annotation function (head groups are formed "
                                "from the head's variables)")

    def aggregation(self, r: Rule) -> None:
        """Quantifiers, annotation function and weights of a rule (docs/language.md)."""
        if r.quantifiers and len(r.quantifiers) != len(r.body):
            raise self.fail(r.loc, f"rule '{r.name}' has {len(r.quantifiers)} quantifier slots for "
                                   f"{len(r.body)} body clauses")
        for q in r.quantifiers:
            if q is None:
                continue
            where = q.loc or r.loc
            if q.op not in COMPARISONS:
                raise self.fail(where, f"unknown comparison '{q.op}' (expected {', '.join(COMPARISONS)})")
            if not q.value >= 0 or (q.percent and q.value > 100) or (not q.percent and q.value != int(q.value)):
                raise self.fail(where, f"bad quantifier {q}: a count is an integer >= 0, a percentage lies in "
                                       "0..100%")
        if r.annotation is not None and not annotations.is_known(r.annotation):
            raise self.fail(r.loc, f"rule '{r.name}': unknown annotation function '{r.annotation}' (built in: "
                                   f"{', '.join(annotations.BUILTINS)}; register others with "
                                   "tracelab.engine.register_annotation)")
        if r.weights:
            if r.annotation is None:
                raise self.fail(r.loc, f"rule '{r.name}' gives weights but its head names no annotation "
                                       "function ('head(X):weighted_average <-...')")
            if len(r.weights) != len(r.body):
                raise self.fail(r.loc, f"rule '{r.name}' gives {len(r.weights)} weights for {len(r.body)} body "
                                       "clauses (one weight per clause)")
            if any(not w >= 0 for w in r.weights):
                raise self.fail(r.loc, f"rule '{r.name}': weights are numbers >= 0")
        if r.aggregated and r.immediate:
            raise self.fail(r.loc, f"rule '{r.name}' is immediate ('<-!'): quantifiers and annotation functions "
                                   "are evaluated per pass over all head groundings, so use '<-0' or a delay")

    def warnings(self) -> Iterable[str]:
        p = self.program
        set_by = {*self.known, *(f.literal.pred for f in p.facts), *(r.head.pred for r in p.rules)}
        warned: set[str] = set()
        for r in self.in_order():
            if isinstance(r, Fact):
                continue
            for lit in r.body:
                if lit.pred not in set_by and lit.pred not in warned:
                    warned.add(lit.pred)
                    where = str(lit.loc) if lit.loc is not None else "<program>"
                    stays = "[0,1] (read as [0,0]: it is %closed)" if lit.pred in p.closed else "[0,1]"
                    yield (f"{where}: warning: predicate '{lit.pred}' is never set by a fact, a rule head or "
                           f"the graph; its atoms stay {stays}")


def _unsafe_why(program: Program, r: Rule, var: str) -> str:
    """Why no body clause of r enumerates var, and what would."""
    uses = [b for b in r.body if var in b.variables]
    if not uses:
        return "it occurs in no body clause; it must occur in a body clause whose bound excludes [0,1]"
    closed = [b for b in uses if b.binds and b.pred in program.closed]
    if closed:
        return (f"it occurs only in body clauses that atoms never set satisfy ('{closed[0].pred}' is %closed, "
                "so its unset atoms read as [0,0]); it must occur in a clause that [0,1] (or [0,0] on a closed "
                "predicate) does not satisfy")
    return ("it occurs only in body clauses whose bound contains [0,1], which every atom satisfies; "
            "it must occur in a body clause whose bound excludes [0,1]")


def _alternatives(xs: list[str]) -> str:
    return xs[0] if len(xs) == 1 else f"{', '.join(xs[:-1])} or {xs[-1]}"


def _args(n: int) -> str:
    return f"{n} argument{'s' if n != 1 else ''}"


def _is_int(x: object) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)

