"""The rule-language parser: the examples of docs/language.md, locations, texts, names, merging files,
syntax errors with their exact positions, and a print-then-parse round trip."""
from __future__ import annotations

import dataclasses
import pickle
import re
from decimal import Decimal
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from located import assert_located
from tracelab.engine import (
    ProgramCheckError,
    ProgramError,
    RuleSyntaxError,
    load_program,
    parse_literal,
    parse_program,
)
from tracelab.engine.parser import CONSTANT_RE
from tracelab.engine.program import Fact, Literal, Rule, SourceLoc, Term

DOCS = Path(__file__).resolve().parent.parent / "docs" / "language.md"


def V(name: str) -> Term:
    return Term(name, True)


def C(name: str) -> Term:
    return Term(name, False)


def L(pred: str, *args: Term, lo: float = 1.0, hi: float = 1.0, neg: bool = False) -> Literal:
    return Literal(pred, args, lo, hi, neg)


def docs_statements() -> str:
    """The example block of the "Statements" section, read from the docs so the two cannot drift apart."""
    text = DOCS.read_text(encoding="utf-8")
    section = text[text.index("## Statements"):]
    return section.split("```")[1]


# ------------------------------------------------------------------------------------ docs examples

def test_docs_statements_parse_to_the_expected_ast() -> None:
    p = parse_program(docs_statements(), "language.md")
    assert p.rules == [
        Rule("m_Down_on", L("moveDown", V("A")),
             (L("agent", V("A")), L("moveDir", V("A"), C("down")), L("atLoc", V("A"), V("X")),
              L("downLoc", V("Y"), V("X")), L("blocked", V("Y"), lo=0.0, hi=0.0)), delay=0),
        Rule("hit", L("hit", V("A")),
             (L("bullet", V("B")), L("atLoc", V("B"), V("X")), L("agent", V("A")), L("atLoc", V("A"), V("X"))),
             immediate=True),
        Rule("clear", L("moveDown", V("A"), lo=0.0, hi=0.0), (L("moveDown", V("A")),), delay=1, mode="override"),
        Rule("lock", L("locked", V("D")), (L("door", V("D")), L("key", V("D"))), delay=1, set_static=True),
        Rule("link", L("linked", V("X"), V("Y")), (L("hub", V("X")), L("joins", V("Y"))), mode="override",
             infer_edges=True),
    ]
    names = [f.name for f in p.facts]
    assert all(re.fullmatch(r"fact\d+", n) for n in names)
    assert [dataclass_tuple(f) for f in p.facts] == [
        (L("agent", C("red-agent-1")), 0, 0, False),
        (L("moveDir", C("red-agent-1"), C("down")), 3, 3, False),
        (L("alarm", C("base"), lo=0.5, hi=1.0), 2, 5, False),
        (L("blocked", C("c12"), lo=0.0, hi=0.0), 0, 0, True),
    ]
    assert (p.mode, p.timesteps, p.inconsistency) == ("override", "reset", "hull")
    assert (p.closed, p.edge_heads) == (("alarm", "hacked"), "graph")
    assert p.files == ["language.md"]


def dataclass_tuple(f: Fact) -> tuple[Literal, int, int, bool]:
    return (f.literal, f.start, f.end, f.static)


def test_rule_text_and_locations() -> None:
    src = ("# header\n"
           "m_Down_on: moveDown(A):[1,1] <-0 agent(A), moveDir(A,down)\n"
           "   ~p(X) <-2 q(X)   # trailing comment\n")
    p = parse_program(src, "r.rules")
    named, unnamed = p.rules
    assert named.loc == SourceLoc("r.rules", 2, 1)
    assert named.head.loc == SourceLoc("r.rules", 2, 12)
    assert [lit.loc.column for lit in named.body] == [34, 44]
    assert named.text == "m_Down_on: moveDown(A):[1,1] <-0 agent(A), moveDir(A,down)"
    assert unnamed.name == "rule3"
    assert unnamed.loc == SourceLoc("r.rules", 3, 4)
    assert unnamed.head == L("p", V("X"), neg=True)
    assert unnamed.head.loc == SourceLoc("r.rules", 3, 4)
    assert unnamed.text == "~p(X) <-2 q(X)"


def test_continuation_lines_join_and_keep_the_first_token_location() -> None:
    src = ("r: h(A) <-1 a(A), \\\n"         # backslash after a comma: both fine
           "      b(A):[.25, 1],   # a comment after the comma still continues\n"
           "\n"
           "      # a comment-only line inside the statement\n"
           "      c(A) \\\n"
           "      {override}\n"
           "s: h(A) <-!\n"
           "   a(A)\n"
           "f: a(x)\n")
    p = parse_program(src, "c.rules")
    r, s = p.rules
    assert r.body == (L("a", V("A")), L("b", V("A"), lo=0.25, hi=1.0), L("c", V("A")))
    assert r.mode == "override" and r.delay == 1
    assert r.text == "r: h(A) <-1 a(A), b(A):[.25, 1], c(A) {override}"
    assert r.body[1].loc == SourceLoc("c.rules", 2, 7)
    assert s.immediate and s.loc == SourceLoc("c.rules", 7, 1) and s.text == "s: h(A) <-! a(A)"
    assert p.facts[0].name == "f" and p.facts[0].loc.line == 9


def test_constants_quoting_and_numbers() -> None:
    p = parse_program('at(red-agent-1, 16)\nat("cell 3", \'x\')\nat("X", _y):[.5,1] <-0 at(_y, "X")\n')
    assert p.facts[0].literal.args == (C("red-agent-1"), C("16"))
    assert p.facts[1].literal.args == (C("cell 3"), C("x"))
    rule = p.rules[0]
    assert rule.head == L("at", C("X"), V("_y"), lo=0.5, hi=1.0)  # a quoted "X" is a constant
    assert rule.body[0].args == (V("_y"), C("X"))


def test_fact_markers_in_either_order_and_named_facts() -> None:
    p = parse_program("start: agent(a) static @3\nagent(b) @3 static\nalarm(x):[0,0.5] @0..0\n")
    assert [(f.name, f.start, f.end, f.static) for f in p.facts] == [
        ("start", 3, 3, True), ("fact2", 3, 3, True), ("fact3", 0, 0, False)]
    assert p.facts[0].text == "start: agent(a) static @3"


def test_comma_separated_options() -> None:
    p = parse_program("h(A) <-0 a(A) {override, override}\nh(A) <-0 a(A) {intersection}\n")
    assert [r.mode for r in p.rules] == ["override", "intersection"]


def test_repeated_directive_with_the_same_value_is_fine() -> None:
    p = parse_program("%mode override\n%mode override\n%inconsistency abort\n")
    assert (p.mode, p.inconsistency, p.timesteps) == ("override", "abort", "persistent")


def test_defaults_without_directives() -> None:
    p = parse_program("")
    assert (p.rules, p.facts, p.mode, p.timesteps, p.inconsistency) == \
        ([], [], "intersection", "persistent", "reset_freeze")


def test_crlf_and_bom() -> None:
    p = parse_program("\ufeffh(A) <-0 a(A),\r\n  b(A)\r\na(x)\r\n", "w.rules")
    assert len(p.rules[0].body) == 2 and p.rules[0].text == "h(A) <-0 a(A), b(A)"
    assert p.facts[0].loc == SourceLoc("w.rules", 3, 1)


# ---------------------------------------------------------------------------------------------- names

def test_generated_names_avoid_explicit_ones() -> None:
    # the unnamed rule on line 1 would be rule1, but a later rule is explicitly named rule1
    p = parse_program("h(A) <-0 a(A)\nrule1: h(A) <-1 a(A)\n", "game.rules")
    assert [r.name for r in p.rules] == ["game_rule1", "rule1"]


def test_load_program_merges_files_and_makes_names_unique(tmp_path: Path) -> None:
    a = tmp_path / "a.rules"
    b = tmp_path / "b.rules"
    a.write_text("%mode override\nh(A) <-0 a(A)\na(x)\n")
    b.write_text("%mode override\nh(A) <-1 a(A)\na(y) @1\n%timesteps reset\n")
    p = load_program(a, str(b))
    assert p.files == [str(a), str(b)]
    assert [r.name for r in p.rules] == ["rule2", "b_rule2"]
    assert [f.name for f in p.facts] == ["fact3", "b_fact3"]
    assert [r.loc.file for r in p.rules] == [str(a), str(b)]
    assert (p.mode, p.timesteps) == ("override", "reset")


def test_load_program_same_stem_gets_a_counter(tmp_path: Path) -> None:
    (tmp_path / "d1").mkdir()
    (tmp_path / "d2").mkdir()
    files = [tmp_path / "x.rules", tmp_path / "d1" / "x.rules", tmp_path / "d2" / "x.rules"]
    for f in files:
        f.write_text("h(A) <-0 a(A)\n")
    assert [r.name for r in load_program(*files).rules] == ["rule1", "x_rule1", "x_rule1_2"]


def test_load_program_conflicting_directive_names_the_second_file(tmp_path: Path) -> None:
    a = tmp_path / "a.rules"
    b = tmp_path / "b.rules"
    a.write_text("%inconsistency hull\n")
    b.write_text("# b\n  %inconsistency abort\n")
    with pytest.raises(ProgramCheckError) as e:
        load_program(a, b)
    assert (e.value.file, e.value.line, e.value.column) == (str(b), 2, 3)
    assert f"conflicting %inconsistency: 'abort' here but 'hull' at {a}:1:1" in e.value.message


def test_load_program_duplicate_rule_name_names_the_second_file(tmp_path: Path) -> None:
    a = tmp_path / "a.rules"
    b = tmp_path / "b.rules"
    a.write_text("go: h(A) <-0 a(A)\n")
    b.write_text("\n\ngo: h(A) <-1 a(A)\n")
    with pytest.raises(ProgramCheckError) as e:
        load_program(a, b)
    assert (e.value.file, e.value.line, e.value.column) == (str(b), 3, 1)
    assert f"duplicate name 'go' (first defined at {a}:1:1)" in str(e.value)


def test_load_program_needs_a_file() -> None:
    with pytest.raises(ValueError):
        load_program()


# --------------------------------------------------------------------------------------- parse_literal

def test_parse_literal() -> None:
    assert parse_literal("atLoc(red-agent-1,16)") == L("atLoc", C("red-agent-1"), C("16"))
    assert parse_literal(" ~alarm(base):[0.5, 1] ") == L("alarm", C("base"), lo=0.5, hi=1.0, neg=True)
    assert parse_literal("atLoc(A, \"cell 3\")") == L("atLoc", V("A"), C("cell 3"))
    assert parse_literal("p(a)  # a comment").loc == SourceLoc("<literal>", 1, 1)


@pytest.mark.parametrize("text,col,fragment", [
    ("atLoc(a,16) x", 13, "expected end of literal, found 'x'"),
    ("", 1, "expected a literal, found end of file"),
    ("p(a):[2,1]", 7, "the lower bound 2 is outside [0,1]"),
    ("p(a", 4, "expected ',' or ')' after an argument of 'p', found end of line"),
])
def test_parse_literal_errors(text: str, col: int, fragment: str) -> None:
    with pytest.raises(ProgramError) as e:
        parse_literal(text)
    assert_located(e.value, "<literal>", 1, col, fragment)


# ------------------------------------------------------------------------------------------ syntax errors

SYNTAX_ERRORS = [
    # text, line, col, fragment of the message
    ("a(x)\n\nh(X) <-0 a(X), b(X)(\n", 3, 20, "expected ',', '{' or end of rule after body literal, found '('"),
    ("h(X) <- a(X)", 1, 8, "expected a delay right after '<-'"),
    ("h(X) <-0 a(X),\n\n# nothing follows\n", 1, 15, "expected a literal after ',', found end of file"),
    ("h(X) <-0", 1, 9, "expected a literal after '<-0', found end of file"),
    ("h(X) <-0 a(X) {", 1, 16, "expected a rule option (intersection | override | set_static | infer_edges | "
                               "weights=w1,w2,...), found end of line"),
    ("h(X) <-0 a(X) {override", 1, 24, "expected '}' or ',' after a rule option, found end of line"),
    ("h(X) <-0 a(X) {override} b(X)", 1, 26, "expected end of rule after the options, found 'b'"),
    ("p(a,b,c)", 1, 6, "expected ')' after the second argument"),
    ("p()", 1, 3, "expected an argument (a constant or a variable), found ')'"),
    ("p(1.5)", 1, 3, "found '1.5' (quote a constant"),
    ("p a", 1, 3, "expected '(' after predicate 'p', found 'a'"),
    ("P(a)", 1, 1, "invalid predicate name 'P'"),
    ("red-x(a)", 1, 1, "invalid predicate name 'red-x'"),
    ("p(X-1)", 1, 3, "invalid variable name 'X-1'"),
    ("p(a) q(a)", 1, 6, "expected '<-k' or '<-!' (a rule), or '@time', 'static' or end of line (a fact)"),
    ("p(a) @3 @4", 1, 9, "expected 'static' or end of line in a fact, found '@'"),
    ("p(a) static static", 1, 13, "expected '@time' or end of line in a fact, found 'static'"),
    ("p(a) @", 1, 7, "expected a time (an integer >= 0) after '@', found end of line"),
    ("p(a) @2..", 1, 10, "expected a time (an integer >= 0) after '..', found end of line"),
    ("p(a) @2.5", 1, 7, "expected a time (an integer >= 0) after '@', found '2.5'"),
    ("p(a):1", 1, 6, "expected '[' after ':'"),
    ("p(a):[1]", 1, 8, "expected ',' between the lower and upper bound, found ']'"),
    ("p(a):[x,1]", 1, 7, "expected the lower bound (a number in [0,1]), found 'x'"),
    ("p(a):[1,1", 1, 10, "expected ']' after the upper bound, found end of line"),
    ('p("a)', 1, 3, "unterminated quoted constant"),
    ('p("")', 1, 3, "empty quoted constant"),
    ("p(a) $", 1, 6, "unexpected character '$'"),
    ("p(a) \\ q(a)", 1, 6, "'\\' continues a statement on the next line and must end its line"),
    ("16: p(a)", 1, 1, "invalid name '16'"),
    (": p(a)", 1, 1, "expected a rule, a fact or a directive, found ':'"),
    ("%foo bar", 1, 2, "unknown directive '%foo' (expected one of %mode, %timesteps, %inconsistency, %edge_heads, "
                       "%closed)"),
    ("%", 1, 2, "expected a directive name after '%', found end of line"),
    ("%mode", 1, 6, "expected a value for %mode (intersection | override), found end of line"),
    ("%mode override extra", 1, 16, "expected end of line after '%mode override', found 'extra'"),
]


@pytest.mark.parametrize("text,line,col,fragment", SYNTAX_ERRORS)
def test_syntax_errors_say_what_was_expected_and_where(text: str, line: int, col: int, fragment: str) -> None:
    with pytest.raises(RuleSyntaxError) as e:
        parse_program(text, "rules/x.rules")
    assert_located(e.value, "rules/x.rules", line, col, fragment)
    assert str(e.value).startswith(f"rules/x.rules:{line}:{col}: error: ")


def test_error_message_shows_the_line_and_a_caret() -> None:
    with pytest.raises(RuleSyntaxError) as e:
        parse_program("a(x)\n\th(X) <-0 a(X)(\n", "rules/x.rules")
    assert str(e.value).splitlines() == [
        "rules/x.rules:2:15: error: expected ',', '{' or end of rule after body literal, found '('",
        "\th(X) <-0 a(X)(",
        "\t             ^",
    ]


def test_program_error_pickles_and_formats_without_position() -> None:
    err = RuleSyntaxError("boom", "f.rules", 3, 2, "abc")
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is RuleSyntaxError and str(back) == str(err) == "f.rules:3:2: error: boom\nabc\n ^"
    assert str(ProgramCheckError("bad value", "g.graphml")) == "g.graphml: error: bad value"


# ---------------------------------------------------------------------------- print-then-parse round trip

def fmt_num(x: float) -> str:
    return format(Decimal(repr(x)), "f")  # positional: the language has no exponents


def fmt_term(t: Term) -> str:
    if t.is_var or CONSTANT_RE.fullmatch(t.name):
        return t.name
    return f"'{t.name}'" if '"' in t.name else f'"{t.name}"'


def fmt_lit(lit: Literal) -> str:
    args = ", ".join(fmt_term(t) for t in lit.args)
    return f"{'~' if lit.negated else ''}{lit.pred}({args}):[{fmt_num(lit.lower)},{fmt_num(lit.upper)}]"


def arity_of(pred: str) -> int:
    return 1 if len(pred) % 2 else 2  # a fixed arity per name keeps random programs free of arity clashes


preds = st.from_regex(r"[a-z][A-Za-z0-9_]{0,5}", fullmatch=True)
variables = st.from_regex(r"[A-Z_][A-Za-z0-9_]{0,3}", fullmatch=True).map(V)
constants = st.one_of(st.from_regex(r"[a-z0-9][A-Za-z0-9_-]{0,6}", fullmatch=True),
                      st.text(st.characters(codec="utf-8", exclude_characters="\"'\n\r"), min_size=1,
                              max_size=6)).map(C)
bounds = st.tuples(st.floats(0, 1), st.floats(0, 1)).map(sorted) | st.sampled_from([(1.0, 1.0), (0.0, 0.0)])


@st.composite
def literals(draw, terms) -> Literal:
    pred = draw(preds)
    lo, hi = draw(bounds)
    args = tuple(draw(terms) for _ in range(arity_of(pred)))
    return Literal(pred, args, lo, hi, draw(st.booleans()))


@st.composite
def rules(draw) -> Rule:
    terms = variables | constants
    head = draw(literals(terms))
    body = draw(st.lists(literals(terms), min_size=1, max_size=4))
    # make it safe: every variable not in a binding clause gets one (a one-letter predicate is unary)
    binding = {v for lit in body if lit.binds for v in lit.variables}
    for lit in (head, *body):
        for v in lit.variables:
            if v not in binding:
                binding.add(v)
                body.append(Literal("b", (V(v),)))
    immediate = draw(st.booleans())
    return Rule("", head, tuple(body), delay=0 if immediate else draw(st.integers(0, 30)),
                immediate=immediate, mode=draw(st.sampled_from([None, "override", "intersection"])))


@st.composite
def facts(draw) -> Fact:
    start = draw(st.integers(0, 50))
    static = draw(st.booleans())
    end = start if static else draw(st.integers(start, 60))
    return Fact("", draw(literals(constants)), start=start, end=end, static=static)


@st.composite
def programs(draw) -> tuple[str, list[Rule | Fact]]:
    """Random statements printed as text, some named, some split over lines; returns the text and the
    statements with the names the parser must give them."""
    items = draw(st.lists(rules() | facts(), max_size=8))
    lines: list[str] = []
    expected: list[Rule | Fact] = []
    for i, it in enumerate(items):
        line = len(lines) + 1
        named = draw(st.booleans())
        name = f"s{i}" if named else f"{'rule' if isinstance(it, Rule) else 'fact'}{line}"
        prefix = f"{name}: " if named else ""
        if isinstance(it, Rule):
            sep = draw(st.sampled_from([", ", ",\n    ", ", \\\n  ", ",  # note\n\n  "]))
            arrow = "<-!" if it.immediate else f"<-{it.delay}"
            opts = f" {{{it.mode}}}" if it.mode else ""
            text = f"{prefix}{fmt_lit(it.head)} {arrow} {sep.join(fmt_lit(b) for b in it.body)}{opts}"
        else:
            marks = [f"@{it.start}..{it.end}" if it.end != it.start else f"@{it.start}"]
            marks += ["static"] if it.static else []
            text = f"{prefix}{fmt_lit(it.literal)} {' '.join(draw(st.permutations(marks)))}"
        lines.extend(text.split("\n"))
        lines.append(draw(st.sampled_from(["", "# comment"])) if draw(st.booleans()) else "")
        expected.append(dataclasses.replace(it, name=name))
    return "\n".join(lines), expected


@settings(max_examples=150, deadline=None)
@given(programs())
def test_printed_programs_parse_back_to_the_same_ast(case: tuple[str, list[Rule | Fact]]) -> None:
    text, expected = case
    p = parse_program(text, "gen.rules")
    assert p.rules == [it for it in expected if isinstance(it, Rule)]
    assert p.facts == [it for it in expected if isinstance(it, Fact)]
    # a statement's text is itself source text for the same statement
    for r in p.rules:
        again = parse_program(r.text).rules
        assert len(again) == 1 and again[0].head == r.head and again[0].body == r.body


def test_a_file_that_is_not_utf8_is_a_located_error(tmp_path: Path) -> None:
    f = tmp_path / "latin1.rules"
    f.write_bytes(b"agent(a)\nname(b, " + "caf\xe9".encode("latin-1") + b")\n")
    with pytest.raises(RuleSyntaxError) as e:
        load_program(f)
    assert (e.value.file, e.value.line, e.value.column) == (str(f), 2, 12)
    assert "not UTF-8 text: byte 0xe9 at byte offset 20" in e.value.message
