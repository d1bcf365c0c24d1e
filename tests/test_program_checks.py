"""The checks made once per program: each error kind with its exact location and message, for parsed
programs and for programs built in code (check_program), and the unused-predicate warnings."""
from __future__ import annotations

from pathlib import Path

import pytest
from tracelab.engine import (
    ProgramCheckError,
    check_program,
    load_program,
    parse_program,
)
from tracelab.engine.program import Fact, Literal, Program, Rule, SourceLoc, Term

X, Y = Term("X", True), Term("Y", True)
a = Term("a", False)


def check_error(text: str) -> ProgramCheckError:
    with pytest.raises(ProgramCheckError) as e:
        parse_program(text, "rules/x.rules")
    return e.value


def at(err: ProgramCheckError) -> tuple[str, int, int]:
    return (err.file, err.line, err.column)


# ------------------------------------------------------------------------------------- parsed programs

CHECK_ERRORS = [
    # text, line, col, fragment of the message
    # arity clashes: reported at the second use, naming the first
    ("p(a)\nq(X) <-0 r(X), p(X,Y), s(Y)", 2, 16,
     "predicate 'p' is used with 2 arguments here but with 1 argument at rules/x.rules:1:1"),
    ("h(X) <-0 e(X,Y), e(Y)", 1, 18, "predicate 'e' is used with 1 argument here but with 2 arguments"),
    # unsafe variables: at the variable's first occurrence
    ("h(X,Y) <-0 a(X)", 1, 5, "unsafe variable 'Y' in rule 'rule1': it occurs in no body clause"),
    ("h(X) <-0 a(X):[0,1]", 1, 3, "unsafe variable 'X' in rule 'rule1': it occurs only in body clauses whose "
                                  "bound contains [0,1]"),
    ("r: h(a) <-0 a(X), \\\n   b(X, Z):[0,1]", 2, 9, "unsafe variable 'Z' in rule 'r'"),
    # bounds: at the offending number (or the '[' when the interval is empty)
    ("p(a):[1.5,1]", 1, 7, "the lower bound 1.5 is outside [0,1]"),
    ("h(X) <-0 a(X):[0, 2]", 1, 19, "the upper bound 2 is outside [0,1]"),
    ("p(a):[-0.5,1]", 1, 7, "the lower bound -0.5 is outside [0,1]"),
    ("p(a):[0.8,.2]", 1, 6, "empty bound [0.8,0.2]: the lower bound must be <= the upper"),
    # facts
    ("agent(a, B)", 1, 10, "a fact must be ground: 'B' is a variable"),
    ("alarm(base) @5..2", 1, 13, "empty window @5..2: the start must be <= the end"),
    ("alarm(base) @-1", 1, 14, "a time is an integer >= 0, found -1"),
    ("blocked(c):[0,0] @2..5 static", 1, 18, "a static fact holds from its time on"),
    # delays, options, directives
    ("h(X) <--1 a(X)", 1, 8, "the delay must be an integer >= 0, found -1"),
    ("h(X) <-99999999999999999999 a(X)", 1, 6,
     "the delay 99999999999999999999 is too large: a delay is at most 1000000000"),
    ("alarm(base) @2..1000000001", 1, 17, "the time 1000000001 is too large: a time is at most 1000000000"),
    ("r: h(X) <-0 " + ", ".join(f"a{i}(X)" for i in range(200)), 1, 1,
     "rule 'r' has 200 binding body clauses; the engine allows at most 127"),
    ("h(X) <-0 a(X) {fast}", 1, 16, "unknown rule option 'fast' (expected intersection | override | set_static | "
                                    "infer_edges | weights=w1,w2,...)"),
    ("h(X) <-0 a(X) {override, intersection}", 1, 26, "conflicting rule options 'override' and 'intersection'"),
    ("%timesteps never", 1, 12, "unknown value 'never' for %timesteps (expected persistent | reset)"),
    ("%inconsistency ignore", 1, 16, "unknown value 'ignore' for %inconsistency"),
    ("\n%mode override\n%mode intersection", 3, 1,
     "conflicting %mode: 'intersection' here but 'override' at rules/x.rules:2:1"),
    # names: one namespace for rules and facts, reported at the second
    ("go: h(X) <-0 a(X)\n\n go: h(X) <-1 a(X)", 3, 2, "duplicate name 'go' (first defined at rules/x.rules:1:1)"),
    ("go: a(x)\ngo: h(X) <-1 a(X)", 2, 1, "duplicate name 'go'"),
]


@pytest.mark.parametrize("text,line,col,fragment", CHECK_ERRORS)
def test_check_errors_name_the_exact_position(text: str, line: int, col: int, fragment: str) -> None:
    err = check_error(text)
    assert at(err) == ("rules/x.rules", line, col), str(err)
    assert fragment in err.message
    assert str(err).startswith(f"rules/x.rules:{line}:{col}: error: {fragment}"[:60])


def test_binding_clauses() -> None:
    # [0,0] binds, and so does a complemented clause; only a bound containing [0,1] does not
    p = parse_program("h(X,Y) <-0 a(X):[0,0], ~b(Y):[0,0.5], c(X,Y):[0,1]\n")
    assert p.rules[0].variables == ("X", "Y")
    # a ground rule needs no binding clause at all
    parse_program("h(a) <-0 b(a):[0,1]\n")


def test_check_error_carries_the_source_line_and_caret() -> None:
    err = check_error("p(a)\nh(X) <-0 a(X), p(X,Y), b(Y)\n")
    assert str(err).splitlines()[1:] == ["h(X) <-0 a(X), p(X,Y), b(Y)", "               ^"]


# ------------------------------------------------------------------------------------ warnings

def test_warning_for_a_body_predicate_nothing_sets() -> None:
    p = parse_program("agent(a)\nh(X) <-0 agent(X), blocked(X):[0,0], blocked(X)\nh2(X) <-0 h(X)\n", "w.rules")
    assert p.warnings == ["w.rules:2:20: warning: predicate 'blocked' is never set by a fact, a rule head "
                          "or the graph; its atoms stay [0,1]"]


def test_known_predicates_silence_warnings_and_clash_on_arity() -> None:
    p = parse_program("h(X) <-0 agent(X), atLoc(X,Y), cell(Y)\n", "w.rules")
    assert len(p.warnings) == 3
    check_program(p, {"agent": 1, "atLoc": 2, "cell": 1})
    assert p.warnings == []  # recomputed, not appended
    with pytest.raises(ProgramCheckError) as e:
        check_program(p, {"atLoc": 1})
    assert at(e.value) == ("w.rules", 1, 20)
    assert "predicate 'atLoc' is used with 2 arguments here but with 1 argument in the graph" in e.value.message


# ------------------------------------------------------------------------------ programs built in code

def loc(line: int, col: int = 1) -> SourceLoc:
    return SourceLoc("m.rules", line, col)


def prog(*items: Rule | Fact, **kw) -> Program:
    return Program(rules=[i for i in items if isinstance(i, Rule)],
                   facts=[i for i in items if isinstance(i, Fact)], files=["m.rules"], **kw)


def lit(pred: str, *args: Term, lo: float = 1.0, hi: float = 1.0, line: int = 1, col: int = 1) -> Literal:
    return Literal(pred, args, lo, hi, loc=loc(line, col))


BUILT_ERRORS = [
    (prog(Fact("f", lit("p", a, lo=0.7, hi=0.2, line=4, col=3), loc=loc(4))), (4, 3),
     "bound [0.7,0.2] of 'p': a bound [l,u] needs 0 <= l <= u <= 1"),
    (prog(Fact("f", lit("p", a, lo=float("nan"), line=2), loc=loc(2))), (2, 1), "a bound [l,u] needs"),
    (prog(Fact("f", lit("p", X, line=5, col=2), loc=loc(5))), (5, 2), "a fact must be ground: 'X'"),
    (prog(Fact("f", lit("p", a), start=4, end=1, loc=loc(7))), (7, 1), "empty window @4..1"),
    (prog(Fact("f", lit("p", a), start=-2, end=1, loc=loc(7))), (7, 1), "fact times are integers >= 0"),
    (prog(Fact("f", lit("p", a, a, a, line=3, col=9), loc=loc(3))), (3, 9), "'p' has 3 arguments"),
    (prog(Fact("f", lit("p", line=3), loc=loc(3))), (3, 1), "'p' has 0 arguments"),
    (prog(Rule("r", lit("h", X), (lit("b", X),), delay=-1, loc=loc(6))), (6, 1),
     "rule 'r': the delay must be an integer >= 0, found -1"),
    (prog(Rule("r", lit("h", X), (lit("b", X),), delay=10**20, loc=loc(6))), (6, 1),
     "rule 'r': the delay 100000000000000000000 is too large: a delay is at most 1000000000"),
    (prog(Fact("f", lit("p", a), start=0, end=2**40, loc=loc(7))), (7, 1), "the time 1099511627776 is too large"),
    (prog(Rule("r", lit("h", X), (lit("b", X),), delay=2, immediate=True, loc=loc(6))), (6, 1),
     "rule 'r' is immediate ('<-!') so its delay is 0, not 2"),
    (prog(Rule("r", lit("h", X), (lit("b", X),), mode="fast", loc=loc(6))), (6, 1), "unknown rule option 'fast'"),
    (prog(Rule("r", lit("h", a), (), loc=loc(6))), (6, 1), "rule 'r' has an empty body"),
    (prog(Rule("r", lit("h", X, line=8, col=4), (lit("b", Y),), loc=loc(8))), (8, 4), "unsafe variable 'X'"),
    (prog(Rule("r", lit("h", X), (lit("b", X),), loc=loc(1)), Rule("r", lit("h", X), (lit("b", X),), loc=loc(9))),
     (9, 1), "duplicate name 'r' (first defined at m.rules:1:1)"),
]


@pytest.mark.parametrize("program,pos,fragment", BUILT_ERRORS)
def test_check_program_on_programs_built_in_code(program: Program, pos: tuple[int, int], fragment: str) -> None:
    with pytest.raises(ProgramCheckError) as e:
        check_program(program)
    assert at(e.value) == ("m.rules", *pos)
    assert fragment in e.value.message


@pytest.mark.parametrize("attr,value,fragment", [
    ("mode", "fast", "unknown %mode 'fast'"),
    ("timesteps", "x", "unknown %timesteps 'x' (expected persistent | reset)"),
    ("inconsistency", "panic", "unknown %inconsistency 'panic'"),
])
def test_check_program_directive_values(attr: str, value: str, fragment: str) -> None:
    program = prog(**{attr: value})
    with pytest.raises(ProgramCheckError) as e:
        check_program(program)
    assert fragment in e.value.message
    assert str(e.value) == f"m.rules: error: {e.value.message}"  # no position for a program-wide value


def test_check_program_without_locations() -> None:
    bad = Program(facts=[Fact("f", Literal("p", (X,)))])
    with pytest.raises(ProgramCheckError) as e:
        check_program(bad)
    assert e.value.file == "<program>" and e.value.line == 0
    good = Program(rules=[Rule("r", Literal("h", (X,)), (Literal("b", (X,)),))])
    check_program(good)
    assert good.warnings == ["<program>: warning: predicate 'b' is never set by a fact, a rule head or the graph; "
                             "its atoms stay [0,1]"]


def test_check_program_reads_the_source_line_back_from_the_file(tmp_path: Path) -> None:
    f = tmp_path / "g.rules"
    f.write_text("agent(a)\nh(X) <-0 agent(X), atLoc(X,Y)\n")
    p = load_program(f)
    with pytest.raises(ProgramCheckError) as e:
        check_program(p, {"atLoc": 1})
    assert str(e.value).splitlines() == [
        f"{f}:2:20: error: predicate 'atLoc' is used with 2 arguments here but with 1 argument in the graph",
        "h(X) <-0 agent(X), atLoc(X,Y)",
        "                   ^",
    ]
